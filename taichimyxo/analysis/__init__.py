"""Quantify what the movies show: clusters, rotating aggregates, speed and strain profiles.

The paper's central testable prediction (Janulevicius et al. 2015, "Circular aggregates as rigid bodies"): aggregates
formed by short-range guiding rotate as rigid bodies, so cell speed grows linearly with the distance from the centre,
the edge speed exceeds v_b (4/3 v_b for adhesion, up to 4 v_b for active following) and does not depend on the
aggregate size; aggregates formed by slime trails move at about v_b everywhere. `analyze()` turns a trajectory into
those numbers (a JSON file) and plots (PNG).

Public API
----------
- ``analyze(gsd_path, out_dir=None, every=1, v_b=None, plots=True, **params) -> dict``: reads the trajectory, writes
  ``<stem>.analysis.json`` and ``<stem>.analysis.<name>.png`` next to it (or in ``out_dir``), returns the summary.
  The command line ``python -m taichimyxo analyze FILE.gsd [--out DIR] [--every K] [--v-b V] [--no-plots]`` (cli.py)
  calls it.
- ``analyze_frames(frames, v_b=4.0, **params) -> dict``: the same on an iterable of ``Frame`` (no files).
- ``format_summary(summary) -> str``: a short human-readable report.
- ``claims(paths, out_dir=None, every=1, v_b=None, plots=True) -> dict``: the paper's claims measured on several runs
  as one table (claims.md, .csv, .json, claims.<name>.png); ``python -m taichimyxo claims RUN.gsd ...`` calls it
  (``claims`` module: the claims, how each is measured and judged). ``format_claims(rows)``: the table as text.
- Building blocks, usable on their own: ``contact_pairs``, ``connected_components``, ``cell_clusters``,
  ``find_aggregates`` (one frame).
- ``synthetic_frames(...)``, ``write_synthetic(...)``: trajectories with known answers (rotating disks, straight
  streams, a gas), used by the tests and the timing benchmark.

Parts (each module's docstring holds its definitions, criteria and thresholds; all defaults in ``DEFAULTS``, every
one can be overridden by keyword): ``params`` (DEFAULTS, the paper's numbers), ``cells`` (per-frame cell geometry:
centres, headings, tangents, speeds), ``clusters`` (contacts, clusters of touching cells), ``aggregates`` (rotating
aggregates in one frame), ``aggregate_measure`` (what is measured on each), ``tracking`` (aggregates across frames by
shared cells: births,
merges, splits, dispersals, lifetimes; the size-independence regression), ``claims`` (the paper's claims table;
``claim_runs``: the runs it reads, ``claim_plots``: its figures),
``summary`` (a whole trajectory, the JSON), ``report`` (the text), ``plots`` (the PNGs), ``synthetic``
(test data), ``stats`` (least squares, binomial tail). The experimental measures (``analyze --measures``,
docs/measures.md): ``measures`` (one pass: ``measure_frames``), ``defects`` (Q field, ±½ defects), ``cluster_sizes``
(fits with a bootstrap), ``correlations`` (velocity and orientation correlations, MSD), ``events`` (reversal intervals,
suppression, guiding links), ``measure_plots``, ``synthetic_measures`` (their test data).

Everything is periodic (minimum image in the box (Lx, Ly)); positions are µm, speeds µm/min, times min.

Cost: per frame O(particles) numpy and scipy (pair search, periodic k-d trees, a few least-squares fits per seed):
a 6-hour, 360-frame synthetic paper-scale trajectory (2000 cells x 8 particles, 10 aggregates, strain logged) takes
31 s wall end to end with the plots (``nice -n 19 python -m taichimyxo analyze paper360.gsd``, one core busy, the
2-core machine under a load of about 4), about 83 ms per frame.

Limitations: detection uses the stored particle velocities; for trajectories without them, speed x forward tangent
(a cell pushed sideways in a jammed core then counts as moving along its body); two counter-rotating aggregates that
touch like gears can exchange a cell or two at the contact; a big aggregate still forming from several swirls may be
found as several pieces; a handful of curled cells in a passive-following crowd can pass as a small (< 10 cells)
aggregate; tracks need the cells' indices to persist through the trajectory (they do in ours); a lifetime is
censored by the start and end of the run (flagged per track).
"""
from .aggregates import find_aggregates
from .claims import claims, format_claims
from .clusters import cell_clusters, connected_components, contact_pairs
from .measures import measure_frames
from .params import DEFAULTS, PAPER
from .report import format_summary
from .summary import analyze, analyze_frames
from .synthetic import synthetic_frames, write_synthetic

__all__ = ["DEFAULTS", "PAPER", "analyze", "analyze_frames", "cell_clusters", "claims", "format_claims",
           "connected_components", "contact_pairs",
           "find_aggregates", "format_summary", "measure_frames", "synthetic_frames", "write_synthetic"]
