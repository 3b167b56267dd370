"""Thresholds of the analysis, with their defaults, and the paper's numbers the results are compared with."""
from __future__ import annotations

import numpy as np

DEFAULTS = dict(
    contact_tol_um=0.3,        # contact when particle distance < W + tol
    min_cells=10,              # smallest cluster that votes / smallest aggregate
    max_radius_um=40.0,        # largest aggregate radius searched (clamped to 0.45 of the box)
    hough_bin_um=1.0,          # Hough grid bin
    ring_um=None,              # ring-walk ring width; None: 2 W
    core_radius_um=None,       # core exempt from the tangential test; None: L / 2
    min_occupancy=0.25,        # ring area occupancy needed to continue the walk
    cos_tangent=0.8,           # heading within acos(0.8) = 36.9° of the tangent counts as circulating
    min_ring_circulating=0.5,  # fraction of a ring's particles circulating
    ring_gap=1,                # the walk bridges this many consecutive bad rings when a good one follows
    min_circulating=0.6,       # fraction of (non-core) member cells circulating
    min_octants=6,             # octants covered by circulating members
    max_p_value=1e-8,          # chance that randomly oriented cells circulate that well (binomial tail)
    edge_fraction=0.2,         # outer fraction of member cells (by radius) that defines the edge speed
    max_candidates=40,         # Hough candidates verified per frame
    max_gap_frames=2,          # tracking: analysed frames an aggregate may be missed
    min_track_frames=3,        # tracking: frames a track needs to enter the across-aggregate regression
    speed_hist_max=24.0,       # µm/min, upper edge of the speed histograms
    speed_hist_bin=0.5,        # µm/min
)

PAPER = {
    "v_b_um_per_min": 4.0,
    "edge_speed_vb_adhesion_rigid_disk": 4.0 / 3.0,
    "edge_speed_vb_active_following_max": 4.0,
    "edge_speed_vb_slime_trails": 1.0,
}

R_BINS = np.linspace(0.0, 1.3, 14)   # r / R bins of the pooled profiles


def parameters(**kw) -> dict:
    """DEFAULTS overridden by kw; an unknown name is an error (a typo would otherwise be ignored silently)."""
    p = dict(DEFAULTS)
    unknown = set(kw) - set(p)
    if unknown:
        raise TypeError(f"unknown analysis parameter(s): {sorted(unknown)}")
    p.update(kw)
    return p


def fill_cell_defaults(P: dict, geo) -> dict:
    """The defaults that scale with the cell (ring width 2 W, core radius L / 2), from a frame's CellGeometry."""
    if P["ring_um"] is None:
        P["ring_um"] = 2.0 * geo.W
    if P["core_radius_um"] is None:
        P["core_radius_um"] = 0.5 * geo.cell_len
    return P
