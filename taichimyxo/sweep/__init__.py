"""Ensembles and parameter sweeps from one file: `python -m taichimyxo sweep FILE [--executor local|slurm] [--jobs N]
[--out DIR] [--dry-run]`.

The sweep file (TOML; examples in sweeps/ of the clone):

    name = "stiffness"          # names the results folder (default: the file's name without .toml)
    description = "..."         # optional, for people
    scene = "S1"                # the base scene: a name as `list` shows it, or a .toml path (relative to this file)
    seeds = 3                   # a count (seeds 1, 2, 3) or a list ([1, 7, 42]); default: the scene's run.seed
    hours = 6                   # simulated hours of every run (default: the scene's run.hours)
    scale = 0.5                 # the box's sides x 0.5, an explicit cell count with the area (a density keeps
                                # itself); or box_um = [100, 100]; values the file sets itself are never scaled
    force = false               # like `scene --force`: a step above the stability limit (the invariants are still
                                # checked at every frame)

    [grid]                      # every combination of these lists is a point; each point runs with every seed
    cell.k_a_N_m = [1e-18, 1e-17, 1e-16, 1e-15]
    guiding.kind = ["none", "active"]

    [[grid]]                    # instead of one [grid]: several, each a product, the points their union (a
    scene = ["S3", "S4"]        # point that resolves to an earlier grid's scene runs once); every grid names
    guiding.pull_on = ["head_particle", "head_segment"]     # its scenes, or none does

    [set]                       # scene keys set the same for every point
    output.frame_interval_min = 2

    [outputs]                   # the trajectory, the run summary and the analysis are always written
    movie = false               # a movie (and its last-frame panel) per run
    analysis_every = 1          # analyse every K-th trajectory frame
    analysis_plots = false      # the analysis's PNGs per run

    [slurm]                     # the options of --executor slurm (taichimyxo.sweep.slurm); [local]: threads = 1

Keys are the scene keys of `python -m taichimyxo keys`, by their dotted names, and `scene`: `[grid] scene = ["S1",
"S3"]` (instead of the top-level `scene`) sweeps base scenes, each with its own values (its step, its guiding), the
box scaled from each one's. A point is named by its values
(`cell.k_a_N_m=1e-17_guiding.kind=active_seed=2`) and keyed by a hash of its resolved scene; it runs in
OUT/runs/NAME-KEY/ (default OUT: sweeps-results/NAME in the current folder), a self-contained folder
(taichimyxo.sweep.runner lists its files). Running the same file again skips the finished runs and resumes the
interrupted ones from their checkpoints; a changed value is a new run in a new folder. OUT/sweep.csv has a row per
run and OUT/sweep.KEY.png the outcomes against each swept key (taichimyxo.sweep.collect).

Every point is resolved and validated before any run starts (an unknown key, an empty list, a value out of range at
any point: one line naming the key and the point). Parts: spec (the file, the points), rundir (a run's folder),
runner (one run), local (the local executor), progress (the status line), collect (the table and plots), orchestrator
(run_sweep and the executors)."""
from .collect import OUTCOMES, collect, outcomes
from .orchestrator import EXECUTORS, executor_module, plan, run_sweep
from .runner import run_point
from .spec import Point, Sweep, SweepError, load_sweep

__all__ = ["EXECUTORS", "OUTCOMES", "Point", "Sweep", "SweepError", "collect", "executor_module", "load_sweep",
           "outcomes", "plan", "run_point", "run_sweep"]
