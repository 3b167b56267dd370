"""Same runs before and after a change: every effect and integrator of the package, run from the same start under an
earlier commit and under the working tree, compared bit for bit (a refactoring must not change one bit of a run).

    python benchmarks/same_runs.py --before COMMIT [--steps 400] [--threads 1] [--out DIR]

Each case is a scene's preview with overrides (guiding kinds, suppression and reversals, slime, strain, a dense
scene, f32 / f64 / mixed precision, mass, error-controlled steps, imex in its three contact modes), run in its own
process (one Simulation per process) in each tree. A case's fingerprint is the SHA-256 of every array its checkpoint
carries and of the forces at its last state. The earlier commit is checked out into a temporary git worktree.
Writes same_runs.csv and exits 1 when any case differs.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

from benchlib import HERE, parser, run_in_tree, worktree, write_csv

REPO = HERE.parent

# name -> (scene, overrides, integrator options)
CASES = {
    "none": ("S1", {}, {}),
    "passive": ("S3", {"guiding": {"kind": "passive"}}, {}),
    "active+strain": ("S3", {}, {}),
    "adhesion": ("S3", {"guiding": {"kind": "adhesion"}}, {}),
    "reversals+suppression": ("S15", {}, {}),
    "reversing without guiding": ("S15", {"guiding": {"kind": "none"}, "reversals": {"suppression": False}}, {}),
    "slime+strain": ("S16", {}, {}),
    "slime+reversals": ("S17", {"reversals": {"enabled": True}}, {}),
    "dense": ("S13", {}, {}),
    "f64": ("S3", {"run": {"precision": "f64"}}, {}),
    "f32": ("S3", {"run": {"precision": "f32"}}, {}),
    "mass": ("S3", {"run": {"mass_pg": 1.0}}, {}),
    "step control": ("S3", {"run": {"step_control": "error", "step_max_multiple": 4}}, {}),
    "imex coupled": ("S13", {"run": {"integrator": "imex"}}, {}),
    "imex diagonal": ("S13", {"run": {"integrator": "imex"}}, {"contacts": "diagonal"}),
    "imex explicit": ("S13", {"run": {"integrator": "imex"}}, {"contacts": "explicit"}),
}

WORKER = r"""
import hashlib, json, sys
import numpy as np
try:                                    # the package's layout in folders
    from taichimyxo.runtime import backend
    from taichimyxo.io.scene import Scene
    import taichimyxo.runtime.simulation as simulation
except ImportError:                     # an earlier commit's flat layout
    from taichimyxo import backend
    from taichimyxo.scene import Scene
    import taichimyxo.simulation as simulation
name, over, options = sys.argv[1], json.loads(sys.argv[2]), json.loads(sys.argv[5])
over.setdefault("output", {})["movie"] = False
sc = Scene.load(name, over, preview=True)
# Taichi as the API starts it for this scene (an f64 scene's literals in f64)
backend.init("cpu", int(sys.argv[3]), default_fp="f64" if sc.precision == "f64" else None)
sim = simulation.Simulation(sc, **options)
steps = int(sys.argv[4])
advance = sim.advance if hasattr(sim, "advance") else sim.run
advance(steps // 2)
advance(steps - steps // 2)
h = hashlib.sha256()
arrays = dict(sim.get_checkpoint())
arrays.update({"force_" + k: v for k, v in sim.forces().items()})
for k in sorted(arrays):
    h.update(k.encode())
    h.update(np.ascontiguousarray(arrays[k]).tobytes())
print(json.dumps({"sha256": h.hexdigest(), "steps": sim.step_count, "rebuilds": sim.rebuilds}))
"""


def fingerprint(tree: Path, case: str, steps: int, threads: int) -> dict:
    scene, over, options = CASES[case]
    return run_in_tree(tree, WORKER, [scene, json.dumps(over), threads, steps, json.dumps(options)])


def main() -> int:
    ap = parser(__doc__)
    ap.add_argument("--before", required=True, help="the earlier commit (or branch) to compare with")
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated case names")
    args = ap.parse_args()
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        print(f"same_runs: unknown case(s) {unknown}; known: {list(CASES)}", file=sys.stderr)
        return 2
    rows, differ = [], 0
    with worktree(args.before) as before:
        for case in cases:
            a = fingerprint(before, case, args.steps, args.threads)
            b = fingerprint(REPO, case, args.steps, args.threads)
            same = a == b
            differ += not same
            rows.append({"case": case, "scene": CASES[case][0], "steps": b["steps"], "rebuilds": b["rebuilds"],
                         "same": same, "before_sha256": a["sha256"][:16], "after_sha256": b["sha256"][:16]})
            print(f"{case:24s} {'same' if same else 'DIFFERENT'}  {a['sha256'][:16]} {b['sha256'][:16]}",
                  flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "same_runs.csv", rows)
    print(f"{len(rows) - differ} of {len(rows)} cases bit-identical to {args.before}; {out / 'same_runs.csv'}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
