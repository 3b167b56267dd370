"""What accuracy costs in time: the wall time of a full 6 h paper-scale S3 against the step and the integrator, each
point marked with what the outcome check says of it (docs/performance.md, "What a faster run gives up").

    python benchmarks/accuracy_cost.py [--steps 1000] [--threads 2] [--out DIR]

Each (integrator, step) is timed in its own process on the late benchmark state (benchmarks/states.py: the
paper-scale S3 as its 6 h run ends), `--steps` steps after a warm-up, and projected to 6 simulated hours at that
cost per step: the late state is what most of a run's hours cost, so the projection is an upper bound (the one real
run, `REAL_RUNS` below, says by how much). The verdicts are read from the committed outcome checks of S3
(benchmarks/results/accuracy_outcomes.csv: half-scale S3, 1 h, six seeds a side against the 2 ms reference): agrees,
differs, or not checked. Writes accuracy_cost.csv, accuracy_cost.md and accuracy_cost.png.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from benchlib import HERE, json_from_worker, parser, write_csv

# (integrator, step in ms): the explicit steps up to the stability limit of S3's stiffnesses (6 ms, docs/accuracy.md),
# imex-explicit up to its limit at k_c = 0.01 N/m (8 ms), imex at the steps it stays within 2 % on speeds
METHODS = [("explicit", 2.0), ("explicit", 3.0), ("explicit", 4.0), ("explicit", 5.0),
           ("imex-explicit", 4.0), ("imex-explicit", 6.0), ("imex-explicit", 8.0),
           ("imex", 10.0), ("imex", 20.0)]
OUTCOMES = HERE / "results" / "accuracy_outcomes.csv"
# real 6 h paper-scale S3 runs through the CLI: (integrator, step ms, wall minutes, where it is recorded)
REAL_RUNS = [("explicit", 4.0, 264.0, "docs/figures.md (the figures' paper-scale S3, 2 cores)")]
SIM_HOURS = 6.0


def verdicts(path: Path = OUTCOMES) -> dict:
    """{(integrator, dt_ms): 'reference' | 'agrees' | 'differs'} by accuracy_outcomes.compare on the runs of an
    outcome check's CSV: the reference is its smallest explicit step, as accuracy_outcomes chooses it; a setting with
    other keys (a step controller, another scene) is not a point of this plot."""
    import accuracy_outcomes
    if not path.is_file():
        return {}
    rows = accuracy_outcomes.read_rows(path)
    points = {}
    for setting in dict.fromkeys(r["setting"] for r in rows):
        keys = json.loads(setting)
        if "run.dt_ms" in keys and not set(keys) - {"run.dt_ms", "run.integrator"}:
            points[setting] = (keys.get("run.integrator", "explicit"), float(keys["run.dt_ms"]))
    explicit = [s for s, (integ, _) in points.items() if integ == "explicit"]
    if not explicit:
        return {}
    reference = min(explicit, key=lambda s: points[s][1])
    cmp = accuracy_outcomes.compare([r for r in rows if r["setting"] in points], reference)
    out = {points[reference]: "reference"}
    for setting, key in points.items():
        if setting != reference:
            out[key] = "differs" if any(c["agrees"] is False for c in cmp if c["setting"] == setting) else "agrees"
    return out


def worker(integrator: str, dt_ms: float, steps: int, threads: int) -> None:
    from states import load
    from taichimyxo.interface.bench import measure
    from taichimyxo.runtime import backend
    backend.init("cpu", threads)
    scene, area, start = load("S3 6 h")
    r = measure(scene, area, steps, 100, run={"integrator": integrator, "dt_ms": dt_ms}, start=start,
                state="S3 6 h")
    print(json.dumps(r), flush=True)


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.2))
    colours = {"explicit": "tab:blue", "imex-explicit": "tab:orange", "imex": "tab:green"}
    style = {"reference": dict(marker="s"), "agrees": dict(marker="o"), "differs": dict(marker="X"),
             "not checked": dict(marker="o", facecolor="none")}
    seen = set()
    for integ in colours:
        pts = [r for r in rows if r["integrator"] == integ]
        ax.plot([r["dt_ms"] for r in pts], [r["projected_6h_min"] for r in pts], color=colours[integ], lw=1)
        for r in pts:
            st = dict(style[r["outcomes"]])
            face = st.pop("facecolor", colours[integ])
            lab = f"{integ}, {r['outcomes']}"
            ax.scatter([r["dt_ms"]], [r["projected_6h_min"]], s=60, edgecolors=colours[integ], facecolors=face,
                       label=None if lab in seen else lab, zorder=3, **st)
            seen.add(lab)
    for integ, dt, minutes, _ in REAL_RUNS:
        ax.scatter([dt], [minutes], marker="*", s=160, color="k", zorder=4, label=f"a real 6 h run ({integ})")
    ax.axhline(90, color="grey", ls=":", lw=1)
    ax.text(2.05, 92, "90 min (issue target)", va="bottom", ha="left", fontsize=8, color="grey")
    ax.set_xscale("log")
    ax.set_xticks([2, 3, 4, 5, 6, 8, 10, 20])
    ax.set_xticklabels(["2", "3", "4", "5", "6", "8", "10", "20"])
    ax.set_xlabel("time step (ms)")
    ax.set_ylabel("6 h paper-scale S3, wall minutes")
    ax.set_title("What accuracy costs: S3 at paper scale, at the 6 h state's cost per step", fontsize=10)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    p = parser(__doc__)
    p.add_argument("--steps", type=int, default=1000, help="steps timed per point (default 1000)")
    p.add_argument("--threads", type=int, default=2, help="CPU threads (default 2)")
    p.add_argument("--worker", nargs=2, metavar=("INTEGRATOR", "DT_MS"), help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.worker:
        worker(a.worker[0], float(a.worker[1]), a.steps, a.threads)
        return
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    methods = METHODS[::3] if a.quick else METHODS
    steps = 200 if a.quick else a.steps
    check = verdicts()
    rows = []
    for integ, dt in methods:
        cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", integ, str(dt), "--steps", str(steps),
               "--threads", str(a.threads)]
        r = json_from_worker(cmd, timeout=3600)
        if "error" in r:
            print(f"accuracy_cost: {integ} {dt:g} ms failed: {r['error']}", flush=True)
            rows.append({"integrator": integ, "dt_ms": dt, "error": r["error"]})
            continue
        n_steps = SIM_HOURS * 3600.0 / (dt * 1e-3)
        row = {"integrator": integ, "dt_ms": dt, "ms_per_step": r["ms_per_step"],
               "rebuilds_per_1000": round(1000.0 * r["rebuilds"] / r["steps"], 1),
               "projected_6h_min": round(n_steps * r["ms_per_step"] * 1e-3 / 60.0, 1),
               "outcomes": check.get((integ, dt), "not checked"), "threads": a.threads, "steps": r["steps"]}
        rows.append(row)
        print(f"{integ:>13} {dt:4g} ms: {row['ms_per_step']:.3f} ms/step, 6 h in {row['projected_6h_min']:.0f} min "
              f"({row['outcomes']})", flush=True)
    good = [r for r in rows if "error" not in r]
    load = [round(x, 2) for x in os.getloadavg()]
    write_csv(out / "accuracy_cost.csv", rows, ["integrator", "dt_ms", "ms_per_step", "rebuilds_per_1000",
                                                 "projected_6h_min", "outcomes", "threads", "steps", "error"])
    lines = ["# What accuracy costs: a 6 h paper-scale S3 against step and integrator", "",
             f"`python benchmarks/accuracy_cost.py --steps {steps} --threads {a.threads}`; each point its own process "
             f"on the S3 6 h state, {steps} timed steps after 100; load average at the end {load}. Outcomes: "
             f"{OUTCOMES.name} (half-scale S3, 1 h, six seeds a side, against 2 ms explicit).", "",
             "| integrator | step, ms | ms/step | rebuilds / 1000 steps | 6 h S3, min (projected) | outcomes |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['integrator']} | {r['dt_ms']:g} | failed: {r['error']} | | | |")
        else:
            lines.append(f"| {r['integrator']} | {r['dt_ms']:g} | {r['ms_per_step']:.3f} | {r['rebuilds_per_1000']:g} "
                         f"| {r['projected_6h_min']:.0f} | {r['outcomes']} |")
    lines += ["", "Real runs: " + "; ".join(f"{i} {d:g} ms, {m:.0f} min ({w})" for i, d, m, w in REAL_RUNS), ""]
    (out / "accuracy_cost.md").write_text("\n".join(lines))
    if good:
        plot(good, out / "accuracy_cost.png")
    print(f"accuracy_cost: {out / 'accuracy_cost.md'}")


if __name__ == "__main__":
    main()
