"""Closest points of two segments: the numpy reference and the Taichi kernel function agree on the hard cases."""
import numpy as np
import pytest
import taichi as ti

from taichimyxo.physics.geometry import closest_points as np_closest
from taichimyxo.runtime import backend

backend.init("cpu")
from taichimyxo.physics.terms.guiding import closest_points as ti_closest  # noqa: E402

CASES = {
    # name: (p1, q1, p2, q2, expected distance, expected s, expected t)
    "crossing": ((0, 0), (2, 2), (0, 2), (2, 0), 0.0, 0.5, 0.5),
    "skew_apart": ((0, 0), (1, 0), (2, 1), (2, 3), np.hypot(1, 1), 1.0, 0.0),
    "parallel_offset": ((0, 0), (2, 0), (1, 0.3), (3, 0.3), 0.3, 0.75, 0.25),   # middle of the overlap [1, 2]
    "collinear_overlap": ((0, 0), (2, 0), (1, 0), (3, 0), 0.0, 0.75, 0.25),
    "collinear_apart": ((0, 0), (1, 0), (2, 0), (3, 0), 1.0, 1.0, 0.0),
    "antiparallel": ((0, 0), (2, 0), (3, 0.4), (1, 0.4), 0.4, 0.75, 0.75),
    "zero_length_first": ((1, 1), (1, 1), (0, 0), (2, 0), 1.0, 0.0, 0.5),
    "zero_length_both": ((0, 0), (0, 0), (3, 4), (3, 4), 5.0, 0.0, 0.0),
    "t_junction": ((0, 0), (2, 0), (1, 0.2), (1, 2), 0.2, 0.5, 0.0),
}


@ti.kernel
def _ti_eval(a: ti.types.ndarray(), out: ti.types.ndarray()):
    for i in range(a.shape[0]):
        p1 = ti.Vector([a[i, 0], a[i, 1]])
        q1 = ti.Vector([a[i, 2], a[i, 3]])
        p2 = ti.Vector([a[i, 4], a[i, 5]])
        q2 = ti.Vector([a[i, 6], a[i, 7]])
        s, t, c1, c2 = ti_closest(p1, q1, p2, q2)
        out[i, 0] = s
        out[i, 1] = t
        out[i, 2] = (c1 - c2).norm()


@pytest.mark.parametrize("name", list(CASES))
def test_numpy_reference(name):
    p1, q1, p2, q2, d, s, t = CASES[name]
    S, T, c1, c2, D = np_closest(p1, q1, p2, q2)
    assert D == pytest.approx(d, abs=1e-12)
    assert S == pytest.approx(s, abs=1e-12)
    assert T == pytest.approx(t, abs=1e-12)


def test_taichi_matches_reference_on_cases_and_random():
    rng = np.random.default_rng(0)
    rows = [np.array(v[:4], float).reshape(-1) for v in CASES.values()]
    rand = rng.uniform(-1, 1, size=(500, 8))
    rand[::7, 6:8] = rand[::7, 4:6] + 1e-3 * rng.uniform(-1, 1, (len(rand[::7]), 2))   # near-degenerate
    a = np.vstack(rows + [rand]).astype(np.float32)
    out = np.zeros((len(a), 3), np.float32)
    _ti_eval(a, out)
    S, T, _, _, D = np_closest(a[:, 0:2], a[:, 2:4], a[:, 4:6], a[:, 6:8])
    np.testing.assert_allclose(out[:, 2], D, atol=2e-5)
    # parameters can differ only where the closest points are not unique (parallel); distances never
    unique = np.abs(out[:, 0] - S) > 1e-3
    for i in np.nonzero(unique)[0]:
        p1, q1, p2, q2 = a[i, 0:2], a[i, 2:4], a[i, 4:6], a[i, 6:8]
        c1 = p1 + out[i, 0] * (q1 - p1)
        c2 = p2 + out[i, 1] * (q2 - p2)
        assert np.linalg.norm(c1 - c2) == pytest.approx(D[i], abs=2e-5)
