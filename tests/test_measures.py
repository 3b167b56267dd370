"""The experimental measures on synthetic data with known answers: defects, cluster sizes, correlations,
MSD; numpy only, no simulation."""
import math

import numpy as np
import pytest
from scipy.special import hyp2f1

from taichimyxo.analysis.cluster_sizes import size_distribution
from taichimyxo.analysis.clusters import cell_clusters
from taichimyxo.analysis.correlations import (
    average_correlations,
    frame_correlations,
    msd,
    uniform_prefix,
    unwrap_tracks,
)
from taichimyxo.analysis.defects import find_defects, orientation_field, track_defects
from taichimyxo.analysis.synthetic_measures import (
    clusters_of_sizes,
    defect_rods,
    exponential_sizes,
    gaussian_field,
    power_law_cutoff_sizes,
    sample_grid,
    walkers,
)
from taichimyxo.physics.geometry import min_image

BOX = np.array([100.0, 100.0])


def _nearest(pos, true):
    return np.array([np.linalg.norm(min_image(pos - t, BOX), axis=1).min() for t in true])


@pytest.mark.parametrize("smoothing,distance", [(2.5, 10.0), (2.5, 20.0), (5.0, 20.0), (5.0, 40.0)])
@pytest.mark.parametrize("noise_deg", [0.0, 15.0, 30.0])
@pytest.mark.parametrize("shift", [(0.0, 0.0), (47.0, 13.0)])
def test_defect_pairs_found_within_one_grid_cell_with_exact_charges(smoothing, distance, noise_deg, shift):
    # a +1/2 and a -1/2 at a set distance (>= 4 smoothing lengths: closer pairs are pulled together), rods at the
    # segment density of the dense scenes S11-S14 (2.8 per µm²), angular noise; shifted so that the pair straddles
    # the periodic edge
    spacing = 2.5
    mid, d, true, q = defect_rods(BOX, [(50 - distance / 2, 50, 0.5), (50 + distance / 2, 50, -0.5)], n_rods=28000,
                                  noise_deg=noise_deg, shift=shift, seed=int(distance + noise_deg))
    pos, charge = find_defects(orientation_field(mid, d, BOX, spacing, smoothing))
    assert len(charge) == 2
    for t, qt in zip(true, q):
        k = np.argmin(np.linalg.norm(min_image(pos - t, BOX), axis=1))
        assert charge[k] == qt
    assert _nearest(pos, true).max() <= spacing


def test_no_defects_in_an_aligned_noisy_field_and_a_close_pair_is_smoothed_away():
    mid, d, _, _ = defect_rods(BOX, [], n_rods=3500, noise_deg=30.0, psi0=0.7)
    assert len(find_defects(orientation_field(mid, d, BOX, 2.5, 5.0))[1]) == 0
    # resolution: a pair closer than about twice the smoothing length annihilates in the field
    mid, d, _, _ = defect_rods(BOX, [(45, 50, 0.5), (55, 50, -0.5)], n_rods=3500)
    assert len(find_defects(orientation_field(mid, d, BOX, 2.5, 5.0))[1]) == 0


def test_empty_regions_have_no_director_and_no_defects():
    mid, d, _, _ = defect_rods(BOX, [(40, 50, 0.5), (60, 50, -0.5)], n_rods=3500)
    keep = mid[:, 0] < 30.0                       # the defects lie in the empty part
    f = orientation_field(mid[keep], d[keep], BOX, 2.5, 2.5)
    assert not f.defined[20:36].any()
    assert len(find_defects(f)[1]) == 0


def test_defects_tracked_across_frames_and_across_the_edge():
    per_frame, truth = [], []
    for k in range(6):
        sx = 12.0 * k                             # the pair drifts right by 12 µm per frame, through the edge
        mid, d, true, q = defect_rods(BOX, [(40, 50, 0.5), (65, 50, -0.5)], n_rods=3500, shift=(sx, 0.0), seed=k)
        per_frame.append(find_defects(orientation_field(mid, d, BOX, 2.5, 5.0)))
        truth.append(true)
    ids = track_defects(per_frame, BOX, max_step_um=15.0)
    assert all(len(i) == 2 for i in ids)
    assert len(set(np.concatenate(ids))) == 2     # two tracks, each through every frame
    for (pos, q), i in zip(per_frame, ids):
        assert set(q[i == i.min()]) == {q[np.argmin(i)]}


def test_cluster_sizes_power_law_with_cutoff_recovered_with_bootstrap_interval():
    s = power_law_cutoff_sizes(3000, alpha=1.5, s_cut=40.0, s_max=2000, seed=1)
    r = size_distribution([s], n_cells=2000, n_boot=100)
    assert r["preferred"] == "power law with cut-off" and r["p_exponential"] < 1e-6
    lo, hi = r["alpha_ci95"]
    assert lo < 1.5 < hi and hi - lo < 0.3
    assert 25 < r["s_cut"] < 60


def test_cluster_sizes_exponential_preferred_for_exponential_data_and_frames_resampled_in_blocks():
    s = exponential_sizes(3000, lam=0.2, seed=2)
    r = size_distribution([s], n_cells=2000, n_boot=100)
    assert r["preferred"] == "exponential"
    assert r["alpha_ci95"][0] < 0.0 < r["alpha_ci95"][1]
    frames = [power_law_cutoff_sizes(200, 1.2, 30.0, s_max=1000, seed=10 + k) for k in range(30)]
    r = size_distribution(frames, n_cells=1000, n_boot=100)
    lo, hi = r["alpha_ci95"]
    assert r["n_frames"] == 30 and lo < r["alpha"] < hi and abs(r["alpha"] - 1.2) < max(0.05, hi - lo)


def test_contact_clusters_of_known_sizes_match_and_freud_agrees():
    import freud
    sizes = np.array([1, 1, 2, 3, 5, 8, 13, 1, 4, 2, 7, 1])
    cells, box = clusters_of_sizes(sizes)
    shift = np.array([0.4 * box[0], 0.3 * box[1]])   # some stacks across the periodic edge
    cells = np.mod(cells + shift, np.array(box))
    N = cells.shape[1]
    cells = cells[:, :1] + min_image(cells - cells[:, :1], np.array(box))
    lab, found, _, _ = cell_clusters(cells, box, 0.5)
    assert sorted(found) == sorted(sizes)
    L = np.array(box)
    p = np.zeros((cells.size // 2, 3), np.float32)
    p[:, :2] = np.mod(cells.reshape(-1, 2), L) - L / 2
    cl = freud.cluster.Cluster().compute((freud.box.Box(L[0], L[1], is2D=True), p),
                                         neighbors={"r_max": 0.8, "exclude_ii": True})
    fl = cl.cluster_idx.reshape(-1, N)[:, 0]
    # the same partition of cells
    assert len(set(zip(lab, fl))) == len(set(lab)) == len(set(fl))


def _gaussian_frame(seed, n=3000, ell=4.0, h=0.5):
    L = np.array([128.0, 128.0])
    f = gaussian_field((256, 256), h, ell, seed=seed, n=4)
    pts = np.random.default_rng(seed).random((n, 2)) * L
    vals = sample_grid(f, h, pts)
    th = 0.5 * np.angle(vals[2] + 1j * vals[3])
    return frame_correlations(pts, np.stack([np.cos(th), np.sin(th)], 1), L, velocities=vals[:2].T, r_max_um=20.0)


def test_velocity_and_orientation_correlations_match_gaussian_fields():
    # velocity components: Gaussian fields of covariance exp(-r²/2ℓ²), so C_v = that and the 1/e length is √2 ℓ;
    # orientation 2θ = arg of a complex Gaussian field: C_n = π/4 ρ 2F1(½, ½; 2; ρ²)
    ell = 4.0
    per = [_gaussian_frame(s, ell=ell) for s in range(3)]
    v, o = average_correlations(per, "velocity"), average_correlations(per, "orientation")
    r = np.asarray(v["r_um"])
    rho = np.exp(-r ** 2 / (2 * ell * ell))
    assert np.abs(np.asarray(v["C"])[:15] - rho[:15]).max() < 0.05
    assert np.abs(np.asarray(o["C"])[:15] - (math.pi / 4 * rho * hyp2f1(0.5, 0.5, 2, rho ** 2))[:15]).max() < 0.05
    assert abs(v["length_um"] - math.sqrt(2) * ell) < 0.5
    assert v["n_frames"] == 3 and np.isnan(v["C_se"][0])        # batch means need 8 frames for an SE


def test_freud_correlation_equals_brute_force_periodic_pairs():
    rng = np.random.default_rng(3)
    L = np.array([30.0, 20.0])
    pts = rng.random((150, 2)) * L
    ang = rng.uniform(0, 2 * np.pi, 150)
    ax = np.stack([np.cos(ang), np.sin(ang)], 1)
    vel = rng.standard_normal((150, 2))
    c = frame_correlations(pts, ax, L, velocities=vel, dr_um=1.0, r_max_um=9.0)
    i, j = np.triu_indices(150, 1)
    d = np.linalg.norm(min_image(pts[j] - pts[i], L), axis=1)
    dv = vel - vel.mean(0)
    b = (d / 1.0).astype(int)
    for k in range(9):
        m = b == k
        if m.sum():
            assert c["orientation"][k] == pytest.approx(np.cos(2 * (ang[i] - ang[j]))[m].mean(), abs=1e-5)
            ref = (dv[i] * dv[j]).sum(1)[m].mean() / (dv * dv).sum(1).mean()
            assert c["velocity"][k] == pytest.approx(ref, abs=1e-5)


@pytest.mark.parametrize("kind,exponent", [("diffusive", 1.0), ("ballistic", 2.0)])
def test_msd_exponent_of_walkers_through_the_periodic_edge(kind, exponent):
    import freud
    box = (60.0, 60.0)
    if kind == "diffusive":
        x, w = walkers(400, 200, box, step_um=1.0, seed=4)
    else:
        x, w = walkers(400, 200, box, step_um=0.0, persistence=1.0, speed=2.0, seed=4)
    tr = unwrap_tracks(w, box)
    np.testing.assert_allclose(tr - tr[0], x - x[0], atol=1e-9)
    m = msd(tr, dt_min=1.0)
    assert abs(m["exponent"] - exponent) < 0.05
    assert m["exponent_se"] < 0.05
    # freud's window MSD gives the same means
    p3 = np.zeros(tr.shape[:2] + (3,))
    p3[..., :2] = tr
    fm = freud.msd.MSD(mode="window").compute(p3).msd
    lags = np.rint(m["lag_min"]).astype(int)
    np.testing.assert_allclose(fm[lags], m["msd_um2"], rtol=2e-3)


def test_uniform_prefix_drops_a_closing_frame_off_the_interval():
    assert uniform_prefix([0, 1, 2, 3, 3.4]) == 4
    assert uniform_prefix([0, 1, 2, 3]) == 4


def _small_run(tmp_path, velocity=True, n_frames=5):
    from taichimyxo.analysis.synthetic import write_synthetic
    return write_synthetic(str(tmp_path / "syn.gsd"), n_frames=n_frames, box=(60.0, 60.0), gas=120, seed=3,
                           disks=[dict(centre=(30, 30), radius=9, omega=0.5)], velocity=velocity)


def test_analyze_with_measures_writes_them_and_their_figures(tmp_path):
    from taichimyxo.analysis import format_summary
    from taichimyxo.interface.api import analyze
    s = analyze(_small_run(tmp_path), out_dir=str(tmp_path / "out"), measures=True)
    ms = s["measures"]
    assert len(ms["defects"]["n_plus_half"]) == 5 and ms["cluster_sizes"]["alpha"] is not None
    assert ms["velocity_correlation"]["n_frames"] == 5
    assert ms["msd"]["exponent"] is not None and ms["events"] is None
    assert [x.split(":")[0] for x in ms["skipped"]] == ["reversal intervals and suppressed reversals"]
    assert any(p.endswith(".defects.png") for p in s["plots"]) and any(p.endswith(".measures.png") for p in s["plots"])
    text = format_summary(s)
    assert "defects (Q field" in text and "skipped: reversal intervals" in text


def test_measures_without_velocities_skip_only_the_velocity_correlation(tmp_path):
    from taichimyxo.analysis.measures import measure_frames
    from taichimyxo.io.trajectory import read_frames
    ms = measure_frames(read_frames(_small_run(tmp_path, velocity=False, n_frames=4)), n_boot=0)
    assert ms["velocity_correlation"] is None and ms["orientation_correlation"] is not None
    assert ms["skipped"][0].startswith("velocity correlation: needs particle velocities")
    assert ms["msd"]["exponent"] is not None and len(ms["defects"]["n_plus_half"]) == 4


def test_cli_measures_with_a_smoothing_length_and_its_events_table(tmp_path, capsys):
    import json

    from taichimyxo.interface.cli import main as cli_main
    from taichimyxo.io.event_table import EventTable
    path = _small_run(tmp_path, n_frames=3)
    t = EventTable(path)
    t.add([30.0, 90.0, 150.0], [1, 2, 3], [4, 4, 4], "reversal")
    t.add(100.0, 2, [5], "suppressed")
    t.close()
    out = tmp_path / "out"
    assert cli_main(["analyze", path, "--smoothing", "2", "--no-plots", "--out", str(out)]) == 0
    ms = json.load(open(out / "syn.analysis.json"))["measures"]
    assert ms["defects"]["smoothing_um"] == 2.0 and ms["defects"]["spacing_um"] == 1.0
    assert ms["events"]["intervals_min"] == [1.0, 1.0] and ms["events"]["fraction_suppressed"] == 0.25
    assert "reversals: 3, interval median 1.0 min" in capsys.readouterr().out
    assert cli_main(["analyze", path, "--smoothing", "-1"]) == 2
