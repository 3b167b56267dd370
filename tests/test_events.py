"""Per-cell events: the event table of a tiny run against the polarity flips in its frames, the reader,
and the statistics analyze reports."""
import numpy as np
import pytest

from taichimyxo.analysis.events import event_stats
from taichimyxo.io.event_table import EventTable, events_path, read_events


def test_event_table_round_trip_and_path(tmp_path):
    t = EventTable(str(tmp_path / "run.gsd"))
    t.add([1.5, 2.5], [10, 20], [3, 4], "reversal")
    t.add(3.0, 30, [3], "link_formed", [7])
    t.close()
    assert events_path(str(tmp_path / "run.gsd")) == str(tmp_path / "run.events.csv")
    ev = read_events(str(tmp_path / "run.gsd"))
    assert ev["kind"].tolist() == ["reversal", "reversal", "link_formed"]
    assert ev["cell"].tolist() == [3, 4, 3] and ev["partner"].tolist() == [-1, -1, 7]
    assert ev["step"].tolist() == [10, 20, 30] and ev["time_s"].tolist() == [1.5, 2.5, 3.0]
    with pytest.raises(FileNotFoundError, match="logged no events"):
        read_events(str(tmp_path / "other.gsd"))


def test_event_stats_intervals_suppression_and_links():
    ev = dict(time_s=np.array([60.0, 660.0, 1260.0, 120.0, 300.0, 400.0, 500.0, 560.0]),
              cell=np.array([0, 0, 0, 1, 1, 2, 2, 2]), partner=np.array([-1, -1, -1, -1, -1, 5, 5, -1]),
              kind=np.array(["reversal"] * 3 + ["reversal", "suppressed", "link_formed", "link_broken",
                                                "suppressed"]))
    s = event_stats(ev, n_cells=3)
    assert s["n_reversals"] == 4 and s["n_suppressed"] == 2
    assert s["fraction_suppressed"] == pytest.approx(2 / 6)
    assert s["intervals_min"].tolist() == [10.0, 10.0]           # cell 1's single reversal gives no interval
    assert s["n_links_formed"] == 1 and s["link_duration_median_min"] == pytest.approx(100 / 60)


def test_logged_reversals_are_the_polarity_flips_in_the_frames(tmp_path):
    import taichimyxo as tm
    from simtools import build_small_scene
    from taichimyxo.io.event_log import EventLog
    from taichimyxo.io.trajectory import read_frames
    from taichimyxo.runtime.simulation import Simulation
    scene = build_small_scene(16, box=(25.0, 25.0), guiding={"kind": "active"}, run={"dt_ms": 2.0},
                              reversals={"enabled": True, "period_min": 0.02, "suppression": True})
    sim = Simulation(scene)
    gsd = str(tmp_path / "run.gsd")
    every = 20                                   # frames 40 ms apart, shorter than the shortest period (120 ms)
    run = tm.run(sim, steps=800, writers=[tm.writers.Trajectory(gsd, trigger=tm.Periodic(steps=every)),
                                          EventLog(gsd)], chunk_steps=300)
    assert run.status == "completed"
    frames = list(read_frames(gsd))
    ev = read_events(gsd)
    rev = ev["kind"] == "reversal"
    counts = sim.model.reversals.rev_count.to_numpy()
    assert rev.sum() == counts.sum() > 10
    supp = getattr(sim.model.reversals, "rev_suppressed", None)
    if supp is not None:
        assert (ev["kind"] == "suppressed").sum() == supp.to_numpy().sum()
    for a, b in zip(frames[:-1], frames[1:]):
        flipped = a.engine_direction != b.engine_direction
        inside = rev & (ev["step"] > a.step) & (ev["step"] <= b.step)
        logged = np.bincount(ev["cell"][inside], minlength=len(flipped))
        np.testing.assert_array_equal(logged % 2 == 1, flipped)
    links = np.isin(ev["kind"], ["link_formed", "link_broken"])
    assert links.any() and (ev["partner"][links] >= 0).all() and (ev["partner"][links] != ev["cell"][links]).all()
    sim.close()
