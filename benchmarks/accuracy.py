"""Accuracy versus cost: each method (integrator, contact treatment, time step, precision) against a
converged reference, and its wall time per simulated hour at paper scale.

    python benchmarks/accuracy.py [--quick] [--out DIR]

What is measured: benchmarks/accuracy_measures.py. Tolerance (SPEED_TOL, STRAIN_TOL) and the defaults it sets:
benchmarks/results/ACCURACY.md. Each method runs in a fresh worker process (accuracy_measures.py): accuracy runs use
one thread each, two at a time; cost runs are serial and use all cores. S3's wall time per simulated hour is taken
at the mean of its start and of S13 (aggregate cores are as dense as S13). Results, in the output folder (default
benchmarks-results/ in the current directory; the study's own results are kept in benchmarks/results/):
accuracy.csv, accuracy.png (error against wall time per simulated hour, one curve per method), accuracy.md (tables).
"""
from __future__ import annotations

import json
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from benchlib import DEFAULT_OUT, HERE, REFERENCE, Method, fmt, json_from_worker, parser, write_csv

# the tolerance that sets the defaults (ACCURACY.md): speeds (free cell, follower, aggregate edge) within 2 % of
# the reference, and the strain energy of dense clusters within 10 % (strain shows how deep cells press into each
# other; larger errors mean the cores of aggregates compact differently: a qualitative change)
SPEED_TOL = 0.02
STRAIN_TOL = 0.10
CACHE = Path(os.environ.get("TAICHIMYXO_BENCH_CACHE", Path.home() / ".cache" / "taichimyxo-bench"))


def _spawn(method: Method, measures: list[str], quick: bool, threads: int, ref_file=None, timeout=1800) -> dict:
    cmd = [sys.executable, str(HERE / "accuracy_measures.py"), "--method", json.dumps(asdict(method)),
           "--measures", ",".join(measures), "--threads", str(threads)] + (["--quick"] if quick else []) + \
          (["--ref", str(ref_file)] if ref_file else [])
    head = {"method": asdict(method), "label": method.label, "family": method.family}
    try:
        r = json_from_worker(cmd, timeout, env=dict(os.environ, TI_LOG_LEVEL="error"))
    except Exception as e:          # noqa: BLE001 - subprocess.TimeoutExpired and the like: one row, not the study
        return {**head, "error": "timeout" if "Timeout" in type(e).__name__ else str(e)[:300]}
    return {**head, **r} if "error" in r else r


def methods(quick: bool) -> list[Method]:
    """The methods of the study. Quick: a few points per family."""
    E, I = "explicit", "imex"
    if quick:
        return [Method(E, dt_ms=2.0, precision="f64"), Method(E, dt_ms=1.0, precision="f32"),
                Method(I, dt_ms=10.0, precision="mixed"), Method(I, dt_ms=50.0, precision="mixed")]
    out = [Method(E, dt_ms=d, precision="f64") for d in (0.5, 1.0, 2.0, 3.0, 4.0, 5.0)]
    out += [Method(E, dt_ms=d, precision="mixed") for d in (1.0, 2.0)]
    out += [Method(E, dt_ms=d, precision="f32") for d in (1.0, 2.0)]
    out += [Method(I, dt_ms=d, precision="mixed") for d in (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)]
    out += [Method(I, dt_ms=d, precision="f32") for d in (5.0, 20.0)]
    out += [Method(I, dt_ms=d, precision="f64") for d in (5.0, 20.0)]
    out += [Method(I, "explicit", dt_ms=d, precision="mixed") for d in (5.0, 10.0, 20.0)]
    out += [Method(I, "diagonal", dt_ms=d, precision="mixed") for d in (5.0, 20.0)]
    out += [Method(I, dt_ms=10.0, precision="mixed", tol=t) for t in (1e-2, 1e-4)]
    return out


def skin_methods(quick: bool) -> list[Method]:
    if quick:
        return []
    skins = (0.15, 0.5, 0.8)          # 0.3 (the default) is in methods()
    base = [Method("explicit", dt_ms=1.0, precision="mixed"), Method("imex", dt_ms=10.0, precision="mixed")]
    return [replace(m, skin_um=s) for m in base for s in skins]


def _rel(a, b):
    return abs(a - b) / abs(b) if b else float("nan")


def errors(r: dict, ref: dict) -> dict:
    """Per-measure errors of one method's raw results against the reference's."""
    e = {}
    if "free_max_dev" in r:
        e["err_free"] = r["free_max_dev"]
    if "follow_speed_vb" in r and "follow_speed_vb" in ref:
        v, vr = np.array(r["follow_speed_vb"]), np.array(ref["follow_speed_vb"])
        k = int(round(r["follow_dt_s"] / ref["follow_dt_s"]))      # the reference samples at least as often
        vr_c = vr[: len(vr) // k * k].reshape(-1, k).mean(1)[: len(v)]
        n = min(len(v), len(vr_c))
        half = max(1, n // 2)
        e["follow_peak_vb"] = float(v.max())
        e["err_follow"] = max(_rel(v.max(), vr_c[:n].max()), _rel(v[:half].mean(), vr_c[:half].mean()))
    for key, name in (("strain_J", "strain"), ("strain01_J", "strain01")):
        if key in r and key in ref:
            s, sr = np.array(r[key]), np.array(ref[key])
            h = len(s) // 2
            e[f"{name}_mean_J"] = float(s[h:].mean())
            e[f"err_{name}"] = _rel(s[h:].mean(), sr[h:].mean())
    if "edge_speed_vb" in r and "edge_speed_vb" in ref:
        e["edge_speed_vb"] = r["edge_speed_vb"]
        e["err_edge"] = _rel(r["edge_speed_vb"], ref["edge_speed_vb"])
    if "horizon_s" in r:
        e["horizon_s"] = r["horizon_s"]
    for m in ("free", "follow", "strain", "strain01", "aggregate", "horizon"):
        if f"{m}_unstable" in r:
            e[f"err_{m if m != 'aggregate' else 'edge'}"] = float("inf")
            if m == "horizon":
                e["horizon_s"] = 0.0
    speeds = [e.get(k) for k in ("err_free", "err_follow", "err_edge") if e.get(k) is not None]
    strains = [e.get(k) for k in ("err_strain", "err_strain01") if e.get(k) is not None]
    e["err_speed"] = max(speeds) if speeds else float("nan")
    e["err_strain_max"] = max(strains) if strains else float("nan")
    e["err_max"] = max(speeds + strains) if speeds + strains else float("nan")
    e["within_tolerance"] = (bool(e["err_speed"] <= SPEED_TOL and e["err_strain_max"] <= STRAIN_TOL)
                             if speeds and strains else "")       # skin rows: follow + horizon only
    return e


def _pool(jobs, workers: int):
    with ThreadPoolExecutor(workers) as ex:
        return list(ex.map(lambda j: _spawn(*j), jobs))


def _cost_key(m: Method) -> tuple:
    # explicit cost does not depend on dt: one per precision
    return (m.integrator, m.contacts, m.precision, m.tol, m.skin_um, m.dt_ms if m.integrator == "imex" else 0)


def main(quick: bool = False, out_dir: str = DEFAULT_OUT) -> int:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    CACHE.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    acc = ["free", "follow", "strain", "strain01", "aggregate", "horizon"]
    reference = REFERENCE
    if quick:       # minutes, not half an hour: fewer measures, shorter runs, a 0.5 ms reference
        acc = ["free", "follow", "strain01", "aggregate", "horizon"]
        reference = replace(REFERENCE, dt_ms=0.5)
    # 1. the reference (also the horizon's reference trajectory)
    ref_file = CACHE / f"reference{'-quick' if quick else ''}.json"
    print(f"reference: {reference.label}", flush=True)
    ref = _spawn(reference, acc, quick, 1)
    if "error" in ref:
        print(f"reference failed: {ref['error']}", file=sys.stderr)
        return 1
    ref_file.write_text(json.dumps({"traj": ref.pop("traj")}))
    # 2. every method, two at a time on one thread each
    ms = methods(quick)
    print(f"{len(ms)} methods, accuracy runs ...", flush=True)
    res = _pool([(m, acc, quick, 1, ref_file) for m in ms], 2)
    # skin: cost only matters (results must not change): accuracy on 'follow' + 'horizon', then cost
    sk = skin_methods(quick)
    res_sk = _pool([(m, ["follow", "horizon"], quick, 1, ref_file) for m in sk], 2)
    # 3. cost, one at a time on all cores
    threads = os.cpu_count() or 1
    print("cost runs ...", flush=True)
    cost_of = {}
    for m in ms + sk + [reference]:
        if _cost_key(m) not in cost_of:
            states = ["cost:start"] if quick else ["cost:start", "cost:dense"]
            cost_of[_cost_key(m)] = _spawn(m, states, quick, threads)
    rows = []
    for r in [ref] + res + res_sk:
        m = Method(**r["method"])
        c = cost_of.get(_cost_key(m), {})
        row = {"label": r["label"], "family": r["family"], **r["method"], **errors(r, ref),
               "error": r.get("error", "")}
        row.update({k: v for k, v in c.items() if k.startswith("cost_")})
        steps_per_h = 3600.0 / (m.dt_ms * 1e-3)
        # S3 over 6 h: from few contacts (its start) to aggregates whose cores are as dense as S13: the mean
        parts = [x for x in (c.get(f"cost_{k}_ms_per_step") for k in ("start", "dense")) if x]
        ms_step = float(np.mean(parts)) if parts else None
        row["wall_s_per_sim_hour"] = steps_per_h * ms_step * 1e-3 if ms_step else float("nan")
        row["skin_study"] = r in res_sk
        rows.append(row)
    write_csv(out / "accuracy.csv", rows, CSV_COLS, ".6g")
    _plot(out / "accuracy.png", [r for r in rows if not r["skin_study"]])
    _write_md(out / "accuracy.md", rows, quick, time.perf_counter() - t_start, reference)
    print(f"wrote {out / 'accuracy.csv'}, {out / 'accuracy.png'}, {out / 'accuracy.md'} "
          f"({time.perf_counter() - t_start:.0f} s)")
    return 0


# ---------------------------------------------------------------------------------------------- outputs
CSV_COLS = ["label", "family", "integrator", "contacts", "dt_ms", "precision", "tol", "skin_um", "skin_study",
            "err_free", "err_follow", "follow_peak_vb", "err_strain", "strain_mean_J", "err_edge", "edge_speed_vb",
            "horizon_s", "err_max", "cost_start_ms_per_step", "cost_start_cpu_ms_per_step",
            "cost_start_cg_per_step", "cost_dense_ms_per_step", "cost_dense_cpu_ms_per_step",
            "cost_dense_cg_per_step", "wall_s_per_sim_hour", "err_strain01", "strain01_mean_J", "err_speed",
            "err_strain_max", "within_tolerance", "error"]


def _plot(path: Path, rows: list[dict]) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    for fam in sorted({r["family"] for r in rows}):
        rs = sorted([r for r in rows if r["family"] == fam and np.isfinite(r.get("wall_s_per_sim_hour", np.nan))],
                    key=lambda r: r["dt_ms"])
        if not rs:
            continue
        x = [r["wall_s_per_sim_hour"] / 60.0 for r in rs]
        y = [max(r.get("err_max", np.nan), 1e-6) if np.isfinite(r.get("err_max", np.nan)) else 10.0 for r in rs]
        ln, = axes[0].loglog(x, y, "o-", label=fam)
        for xi, yi, r in zip(x, y, rs):
            axes[0].annotate(f"{r['dt_ms']:g}", (xi, yi), fontsize=7, textcoords="offset points", xytext=(3, 3))
        h = [r.get("horizon_s", np.nan) / 60.0 for r in rs]
        axes[1].semilogx(x, h, "o-", color=ln.get_color(), label=fam)
    axes[0].axhline(SPEED_TOL, color="k", lw=0.8, ls="--")
    axes[0].axhline(STRAIN_TOL, color="k", lw=0.8, ls=":")
    axes[0].set_xlabel("wall time per simulated hour, S3 paper scale, 2 cores (min)")
    axes[0].set_ylabel("max relative error (speeds, strain energies)")
    axes[0].set_title("error vs cost (labels: dt in ms; tolerances: speeds --, strain :)")
    axes[1].set_xlabel("wall time per simulated hour, S3 paper scale, 2 cores (min)")
    axes[1].set_ylabel("horizon: time within W of the reference (min)")
    axes[1].set_title("50-cell chaotic patch")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _write_md(path: Path, rows: list[dict], quick: bool, wall: float, reference: Method) -> None:
    cols = [("label", "method"), ("err_free", "free-cell speed dev"), ("err_follow", "follower speed err"),
            ("follow_peak_vb", "follower peak (v_b)"), ("err_strain", "strain err"), ("err_edge", "edge speed err"),
            ("edge_speed_vb", "edge (v_b)"), ("horizon_s", "horizon (s)"),
            ("err_strain01", "strain err k_c=0.01"),
            ("cost_start_ms_per_step", "ms/step S3 start"), ("cost_dense_ms_per_step", "ms/step S13 dense"),
            ("cost_dense_cg_per_step", "CG it/step dense"), ("wall_s_per_sim_hour", "wall min / sim h"),
            ("within_tolerance", "within tol")]
    lines = [f"# Accuracy versus cost{' (quick)' if quick else ''}", "",
             f"Generated by `python benchmarks/accuracy.py{' --quick' if quick else ''}` in {wall / 60:.1f} min "
             f"on {os.cpu_count()} cores. Reference: {reference.label}. Errors are relative to the reference "
             "(free cell: to v_b). See ACCURACY.md for the reading.", "",
             "| " + " | ".join(c[1] for c in cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        vals = []
        for k, _ in cols:
            v = r.get(k, float("nan"))
            if k == "wall_s_per_sim_hour" and isinstance(v, float):
                v = v / 60.0
            vals.append(fmt(v))
        lines.append("| " + " | ".join(vals) + " |")
    path.write_text("\n".join(lines) + "\n")


def build_parser():
    return parser(__doc__, "reduced version (a few minutes): 4 methods, shorter runs, a 0.5 ms reference")


if __name__ == "__main__":
    a = build_parser().parse_args()
    raise SystemExit(main(quick=a.quick, out_dir=a.out))
