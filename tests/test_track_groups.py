"""Rotating groups from centroid tracks (analysis/track_groups.py), the degradations of analysis/lab_tracks.degrade,
the mechanism report (analysis/mechanism_report.py) and the `tracks` command, on synthetic tracks whose answers are
known: a rigid disk, a ring of cells at v_b, straight streams, a bend, jammed cells, a disk across the periodic edge,
and synthetic runs standing for each mechanism."""
import json

import numpy as np
import pytest

from taichimyxo.analysis.lab_tracks import degrade
from taichimyxo.analysis.mechanism_report import compare, in_group_speeds, sentence
from taichimyxo.analysis.track_groups import find_groups, group_speeds, resample
from taichimyxo.interface.cli import main
from taichimyxo.io.tracks import assemble

F = 30.0                                          # frame interval, s
T = np.arange(60) * F
V = 4.0                                           # v_b, µm/min


def disk(rng, centre=(30.0, 30.0), R=8.0, edge=2.0 * V, n=30, sense=1, uniform=False):
    """Cells spread over a disk rotating rigidly (edge speed `edge` µm/min), or each at speed edge (uniform)."""
    out = []
    for _ in range(n):
        r = R * np.sqrt(rng.uniform(0.1, 1.0))
        om = (edge / r if uniform else edge / R) / 60.0 * sense
        ph = rng.uniform(0, 2 * np.pi)
        out.append((T, np.c_[centre[0] + r * np.cos(ph + om * T), centre[1] + r * np.sin(ph + om * T)]))
    return out


def gliders(rng, n=40, lo=60.0, hi=140.0, v=V):
    out = []
    for _ in range(n):
        a = rng.uniform(0, 2 * np.pi)
        out.append((T, rng.uniform(lo, hi, 2) + np.c_[np.cos(a), np.sin(a)] * (v / 60.0 * T)[:, None]))
    return out


def tracks_of(parts, rng=None, noise=0.0, box=None):
    ids = np.concatenate([np.full(len(t), k) for k, (t, _) in enumerate(parts)])
    ts = np.concatenate([t for t, _ in parts])
    xy = np.concatenate([p for _, p in parts])
    if noise:
        xy = xy + rng.normal(0, noise, xy.shape)
    return assemble(ids, ts, xy, F, box=box)


def test_a_rigid_disk_is_one_group_with_its_centre_radius_and_linear_speed_profile():
    rng = np.random.default_rng(1)
    tr = tracks_of(disk(rng) + gliders(rng), rng, noise=0.1)
    pts, groups = find_groups(tr)
    frames = {g["frame"] for g in groups}
    assert len(groups) == len(frames) >= 50                       # one group a frame
    assert all(np.hypot(g["centre_um"][0] - 30, g["centre_um"][1] - 30) < 0.5 for g in groups)
    assert np.median([g["radius_um"] for g in groups]) == pytest.approx(8.0, abs=0.5)
    s = group_speeds(pts, groups)
    assert s["v_ref_um_per_min"] == pytest.approx(V, rel=0.03)   # the gliders' speed
    prof = np.array(s["profile_speed_vref"][1:])
    assert np.all(np.diff(prof) > 0)                                 # rigid rotation: faster outwards
    # speeds r / R x 2 v_b; the edge band 2/3..1 averages about 1.7 v_b
    assert s["edge_speed_median_vref"] == pytest.approx(1.7, abs=0.12)
    assert s["speed_out_median_vref"] == pytest.approx(1.0, abs=0.03)


def test_a_ring_at_v_b_reads_v_b_inside_as_outside():
    rng = np.random.default_rng(2)
    tr = tracks_of(disk(rng, edge=V, uniform=True) + gliders(rng), rng, noise=0.05)
    s = group_speeds(*find_groups(tr))
    assert s["speed_in_median_vref"] == pytest.approx(1.0, abs=0.06)
    assert s["edge_speed_median_vref"] == pytest.approx(1.0, abs=0.06)


def test_streams_a_bend_and_jammed_cells_are_no_group():
    rng = np.random.default_rng(3)
    stream = [(T, np.c_[10 + 4 / 60 * T + 0.6 * k, np.full(len(T), 20.0 + 0.5 * (k % 4))]) for k in range(12)]
    # a stream turning 90 degrees around (50, 50) at radius 10: a quarter circle, then straight on
    bend = []
    for k in range(8):
        s = 4 / 60 * T - 1.2 * k                                   # arc length along the path
        ang = np.clip(s / 10.0, 0, np.pi / 2)
        x = np.where(s < 0, 60 + 0 * s, 50 + 10 * np.cos(ang))
        y = np.where(s < 0, 50 + s, 50 + 10 * np.sin(ang))
        after = s > 10 * np.pi / 2
        x = np.where(after, 50 - (s - 10 * np.pi / 2), x)
        y = np.where(after, 60.0, y)
        bend.append((T, np.c_[x, y]))
    jammed = [(T, np.full((len(T), 2), [90.0 + k % 5, 90.0 + k // 5]) + 0.0) for k in range(20)]
    tr = tracks_of(stream + bend + jammed, rng, noise=0.15)
    _, groups = find_groups(tr)
    assert groups == []


def test_a_disk_across_the_periodic_edge_is_found_once_a_frame():
    rng = np.random.default_rng(4)
    # unwrapped as from_frames gives them: each track continuous from where its first point lies in the box
    parts = [(t, xy + [100.0 * (xy[0, 0] < 0), 0.0]) for t, xy in disk(rng, centre=(1.0, 50.0))]
    assert 5 < sum(xy[0, 0] > 50 for _, xy in parts) < 25
    tr = tracks_of(parts, box=(100.0, 100.0))
    _, groups = find_groups(tr)
    assert len(groups) == len({g["frame"] for g in groups}) >= 50
    c = np.mod(np.array([g["centre_um"] for g in groups]), 100.0)
    assert np.all(np.abs((c[:, 0] - 1.0 + 50) % 100 - 50) < 0.5)
    assert all(g["members"] == 30 for g in groups[5:-5])


def test_degrade_keeps_clean_tracks_and_counts_what_it_breaks():
    rng = np.random.default_rng(5)
    tr = tracks_of(gliders(rng, n=20))
    same = degrade(tr)
    assert same.counts["tracks_kept"] == 20 and np.allclose(same.tracks[3][1], tr.tracks[3][1])
    coarse = degrade(tr, frame_s=60.0)
    assert coarse.frame_s == 60.0 and len(coarse.tracks[0][0]) == 30
    holes = degrade(tr, seed=1, missed=0.3)                          # runs of > 2 missing frames split tracks
    assert holes.counts["split_at_gaps"] > 0 and holes.n_points < 0.8 * tr.n_points
    # swaps between far-apart gliders are jumps no cell makes: cut and counted
    swapped = degrade(tr, seed=2, swaps_per_track_hour=2.0)
    assert swapped.counts["split_at_jumps"] > 0
    assert resample(tr, 90.0).frame_s == 90.0


def _mechanism(seed, edge, uniform=False, n_disks=3):
    rng = np.random.default_rng(seed)
    parts = []
    for k in range(n_disks):
        parts += disk(rng, centre=(30.0 + 50 * k, 30.0), edge=edge, uniform=uniform, sense=1 - 2 * (k % 2))
    return tracks_of(parts + gliders(rng, lo=20, hi=160), rng, noise=0.1)


MECHS = {"active following": dict(edge=2.5 * V), "adhesion": dict(edge=4 / 3 * V),
         "slime trails": dict(edge=V, uniform=True)}


@pytest.mark.parametrize("truth", list(MECHS))
def test_the_report_names_the_mechanism_a_synthetic_measurement_was_made_by(truth):
    refs = {m: [in_group_speeds(_mechanism(10 + i, **kw), v_b=V) for i in range(2)] for m, kw in MECHS.items()}
    meas = in_group_speeds(_mechanism(99, **MECHS[truth]))           # v_b read from the gliders
    res = compare(meas, refs, n_boot=100)
    assert res["nearest"] == truth and res["strength"] == "strong", res["why"]


def test_the_report_cannot_tell_without_points_in_groups_or_between_equal_mechanisms():
    rng = np.random.default_rng(6)
    refs = {m: [in_group_speeds(_mechanism(20, **kw), v_b=V)] for m, kw in MECHS.items()}
    none = compare(in_group_speeds(tracks_of(gliders(rng))), refs, n_boot=50)
    assert none["verdict"] == "cannot tell" and "rotating groups" in none["why"]
    twins = {"a": [in_group_speeds(_mechanism(30, **MECHS["adhesion"]), v_b=V)],
             "b": [in_group_speeds(_mechanism(31, **MECHS["adhesion"]), v_b=V)]}
    res = compare(in_group_speeds(_mechanism(32, **MECHS["adhesion"])), twins, n_boot=100)
    assert res["strength"] != "strong"


def test_the_report_says_when_the_nearest_mechanism_does_not_fit():
    refs = {m: [in_group_speeds(_mechanism(40 + i, **kw), v_b=V) for i in range(2)] for m, kw in MECHS.items()}
    res = compare(in_group_speeds(_mechanism(99, edge=3.5 * V), v_b=V), refs, n_boot=100)
    assert res["nearest"] == "active following" and not res["fits"]
    assert "none of the simulated mechanisms fits" in sentence(res)
    same = compare(in_group_speeds(_mechanism(98, **MECHS["active following"]), v_b=V), refs, n_boot=100)
    assert same["fits"] and "fits" not in sentence(same)


def test_tracks_command_reads_a_csv_and_compares_with_runs(tmp_path, capsys):
    from taichimyxo.analysis.synthetic import write_synthetic
    runs = tmp_path / "refs"
    runs.mkdir()
    kinds = {"active following": ({"guiding": {"kind": "active"}}, dict(omega=2.5 * V / 8.0)),
             "adhesion": ({"guiding": {"kind": "adhesion"}}, dict(omega=4 / 3 * V / 8.0)),
             "slime trails": ({"guiding": {"kind": "none"}, "slime": {"enabled": True}}, dict(omega=1.0, speed=V))}
    for i, (m, (scene, d)) in enumerate(kinds.items()):
        for seed in (1, 2):
            write_synthetic(str(runs / f"{i}_{seed}.gsd"), scene=scene, n_frames=40, dt_s=30.0, box=(120.0, 120.0),
                            disks=[dict(centre=(30, 30), radius=8.0, **d), dict(centre=(90, 90), radius=8.0, **d)],
                            gas=40, gas_avoids_disks=True, seed=seed)
    # the measured: an adhesion-like run's centroids written as a lab's CSV, in pixels of 0.5 µm and frames
    from taichimyxo.interface.tracks_api import tracks_from_run
    meas = str(runs / "1_1.gsd")
    tr = tracks_from_run(meas)
    csv = tmp_path / "spots.csv"
    with open(csv, "w") as f:
        f.write("track,frame,x,y\n")
        for k, (t, xy) in enumerate(tr.tracks):
            for ti, (x, y) in zip(t, xy):
                f.write(f"{k},{ti / 30.0:g},{x / 0.5:.3f},{y / 0.5:.3f}\n")
    out = tmp_path / "report"
    assert main(["tracks", str(csv), "--pixel-um", "0.5", "--frame-s", "30", "--time-unit", "frame", "--v-b", "4",
                 "--against", str(runs), "--boot", "100", "--out", str(out)]) == 0
    res = json.loads((out / "report.json").read_text())
    assert res["nearest"] == "adhesion"
    assert (out / "report.png").stat().st_size > 0 and "adhesion" in (out / "report.md").read_text()
    assert "adhesion" in capsys.readouterr().out


def test_tracks_command_refuses_bad_input_in_one_line_before_writing(tmp_path, capsys):
    csv = tmp_path / "t.csv"
    csv.write_text("track,time,x,y\n0,0,1,1\n0,30,2,2\n")
    out = tmp_path / "out"
    for args, words in ((["--against", str(tmp_path / "nothing")], "no such file"),
                        (["--against", str(tmp_path)], "no simulated run"),
                        (["--v-b", "-1"], "--v-b")):
        assert main(["tracks", str(csv), "--out", str(out), *args]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err
        assert not out.exists()
