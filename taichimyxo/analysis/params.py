"""Thresholds of the analysis, with their defaults, and the paper's numbers the results are compared with."""
from __future__ import annotations

import numpy as np

DEFAULTS = dict(
    contact_tol_um=0.3,        # contact when particle distance < W + tol
    min_cells=4,               # smallest aggregate (cells): S3 at 60 min has a 4-5-cell curl a person counts
    confirm_by_neighbours=True,  # an aggregate counts when it is also seen in the previous or next analysed frame
    max_radius_um=40.0,        # largest aggregate radius searched (clamped to 0.45 of the box)
    min_cell_speed_vb=0.1,     # a cell slower than this x v_b gives no rotation centre and circulates about none
    seed_radius_um=1.5,        # cells' own rotation centres this close count together (3 W)
    min_seed_cells=3,          # own centres needed for a seed
    max_seeds=400,             # seeds per frame and sense at most
    centre_tol=1.0,            # a cell's own centre must lie within this x its distance from the aggregate centre
    refine_iterations=3,       # assignment / centre refinement / merge rounds
    merge_circulation=0.75,    # two groups of one sense merge when their union circulates this well
                               # (see min_circulation)
    ring_um=None,              # ring width of the speed-vs-radius profile; None: 2 W
    core_radius_um=None,       # core: cells closer to the centre join without the tangential test; None: L / 2
    cos_tangent=0.8,           # velocity within acos(0.8) = 36.9° of the tangent counts as circulating
    min_coverage=0.75,         # fraction of 16 angular sectors the member particles cover
    min_circulation=0.5,       # mean cos(angle between velocity and the tangent) over member particles
    min_inside_fraction=0.4,   # members among the cells inside the aggregate
    min_circulation_r2=0.5,    # fraction of the velocity variance that is circulation about the centre
    max_gap_frames=2,          # tracking: analysed frames an aggregate may be missed
    link_overlap=0.3,          # tracking: shared cells / members of the smaller aggregate for a link
    link_min_shared=2,         # tracking: shared cells for a link at least
    stable_lifetime_min=10.0,  # tracking: a track living this long (min) is long-lived ("stable")
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
