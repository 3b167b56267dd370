"""Rigid-body check: the edge speed of pre-formed (spiral-start) aggregates in the simulator against the rigid-body
model (taichimyxo/analysis/rigid_body.py): (a) the paper's ideal disk, (4/3) v_b for adhesion and at most 4 v_b for
active following, and (b) the torque balance on the very configuration the simulator holds.

Cases: spiral starts (placement.spiral_start, as S9/S10 set it) of outer radius about 5, 10 and 20 µm (the cells
chosen from placement.spiral_capacity's spiral so the outermost particle + W/2 is nearest the target; box 2R + 30 µm),
guiding adhesion and active, drag ratio zeta_n / zeta_t 0.5, 1, 2, rigid cells (k_a = 1e-16 N·m) and optionally
flexible ones (--flexible: 1e-17 N·m at drag ratio 0.5). Each case runs --minutes simulated minutes; at each sample
time the particles' velocities are measured over a --window-s window (displacement / window, minimum image) and

- omega: least squares of v = omega z x (x - c) over the aggregate's particles (analysis.stats.rigid_rotation_fit;
  c fitted too); the aggregate: cells whose centre lies within R0 + L/2 of c (R0: the start's outer radius);
- R: the outermost member particle's distance + W/2; edge speed: the mean speed of member particles at r >= R - W;
- model (b): rigid_motion of the window's mid positions about c with the guiding pulls the simulator applied
  (its g_head, and for adhesion g_tail, averaged over the window), edge speed |omega_b| times the mean r of the same
  edge particles; also without pulls (the paper's adhesion reading) and with every cell at F_max (active maximum);
- why they differ: the omega(r) profile (mean tangential velocity / r per quarter of R), the rigidity exponent
  (slope of ln speed on ln r), the cells' alignment with circles (mean (p.u)^2 / p^2: 0 along circles), the pulls
  (mean, share at >= 0.9 F_max), and the torque identity (drag torque of the measured velocities / drive torque,
  1 whatever the motion when internal forces carry no torque).

The table uses the mean over the samples at t >= 1 min. Writes rigid_body_check.md and .json into --out
(default benchmarks-results/ in the current directory; `--out benchmarks/results` updates the committed result).

    nice -n 5 python benchmarks/rigid_body_check.py --out benchmarks/results      # ~20 min of one core
    python benchmarks/rigid_body_check.py --quick                                   # one small case, 30 s simulated
"""
from __future__ import annotations

import json
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from benchlib import DEFAULT_OUT, parser

RIGID_KA, FLEXIBLE_KA = 1e-16, 1e-17


def spiral_cells_for_radius(R_target: float, box: float) -> tuple[int, float]:
    """The number of spiral cells whose outer radius (outermost particle + W/2) is nearest R_target."""
    from taichimyxo.io.scene import Scene
    from taichimyxo.physics.placement import spiral_capacity, spiral_start
    sc = Scene.load("S9", {"domain": {"width_um": box, "height_um": box}, "population": {"cells": 1}})
    n_max = spiral_capacity(sc)
    sc = sc.with_overrides({"population": {"cells": n_max}})
    pos, _ = spiral_start(sc)
    c = 0.5 * np.array(sc.box)
    r_cell = np.linalg.norm(pos - c, axis=-1).max(1)
    R_n = np.maximum.accumulate(r_cell) + sc.width / 2          # outer radius of the first n cells, n = 1..n_max
    n = int(np.argmin(np.abs(R_n - R_target))) + 1
    return n, float(R_n[n - 1])


def case_scene(R_target: float, kind: str, rho: float, k_a: float):
    from taichimyxo.io.scene import Scene
    box = round(2 * R_target + 30.0)
    n, R0 = spiral_cells_for_radius(R_target, box)
    sc = Scene.load("S9", {"domain": {"width_um": box, "height_um": box}, "population": {"cells": n},
                           "guiding": {"kind": kind}, "cell": {"drag_ratio_normal": rho, "k_a_N_m": k_a},
                           "output": {"movie": False}})
    return sc, R0


def measure(sim, sc, R0: float, window_s: float, n_sub: int = 6) -> dict:
    """One window's velocities, pulls and the model on them (module docstring)."""
    from taichimyxo.analysis.aggregate_measure import rigidity_exponent
    from taichimyxo.analysis.rigid_body import cell_axes, drag_torque, rigid_motion
    from taichimyxo.analysis.stats import rigid_rotation_fit
    from taichimyxo.physics.geometry import min_image
    box = np.array(sc.box)
    W, L, v_b, rho, Fe, Fmax = (sc.width, sc.length, sc.v_b_um_per_min, sc.raw["cell"]["drag_ratio_normal"],
                                sc.engine_force, sc.guiding_f_max)
    ht = sim.model.head_to_tail
    n_w = max(n_sub, int(round(window_s / sc.dt)))
    per = n_w // n_sub
    p0 = sim.positions()
    gh = np.zeros((sc.n_cells, 2))
    gt = np.zeros((sc.n_cells, 2))
    for _ in range(n_sub):
        sim.advance(per)
        gh += ht.g_head.to_numpy()
        if ht.g_tail is not None:
            gt += ht.g_tail.to_numpy()
    gh /= n_sub
    gt /= n_sub
    T_min = n_sub * per * sc.dt / 60.0
    p1 = sim.positions()
    d = min_image(p1 - p0, box)
    v = d / T_min                                             # µm/min
    pm = p0 + 0.5 * d
    ke = sim.engine_direction()
    N = sc.N
    c = 0.5 * box
    for _ in range(3):                                        # members and centre, iterated
        cen = pm.mean(1)
        members = np.linalg.norm(min_image(cen - c, box), axis=1) <= R0 + L / 2
        fit = rigid_rotation_fit(pm[members].reshape(-1, 2), v[members].reshape(-1, 2))
        if not np.all(np.isfinite(fit["centre"])):
            break
        c = np.asarray(fit["centre"])
    pts, vel = pm[members].reshape(-1, 2), v[members].reshape(-1, 2)
    p = pts - c
    r = np.linalg.norm(p, axis=1)
    speed = np.linalg.norm(vel, axis=1)
    R = float(r.max()) + W / 2
    edge = r >= R - W
    v_edge = float(speed[edge].mean())
    r_edge = float(r[edge].mean())
    vt = (p[:, 0] * vel[:, 1] - p[:, 1] * vel[:, 0]) / np.maximum(r, 1e-9)
    sense = -1.0 if fit["omega"] < 0 else 1.0
    prof = []
    for lo, hi in ((0.0, 0.25), (0.25, 0.5), (0.5, 0.75), (0.75, 1.01)):
        m = (r >= lo * R) & (r < hi * R) & (r > W)
        prof.append(float(np.mean(sense * vt[m] / r[m])) if m.any() else float("nan"))
    # the simulator's pulls as external forces: g_head on head particles; adhesion's reaction g_tail on tails
    extra = np.zeros_like(pm)
    idx = np.arange(sc.n_cells)
    tails = np.where(ke > 0, N - 1, 0)
    extra[idx, tails] += gt
    kw = dict(v_b=v_b, drag_ratio_normal=rho, engine_force_pN=Fe, centre=c, mask=members)
    mb = rigid_motion(pm, ke, guiding_pull_pN=gh, extra_force_pN=extra, **kw)
    m0 = rigid_motion(pm, ke, **kw)
    mmax = rigid_motion(pm, ke, guiding_pull_pN=Fmax, **kw)
    mfree = rigid_motion(pm, ke, guiding_pull_pN=gh, extra_force_pN=extra, translate=True, **kw)
    tq = drag_torque(pm, ke, v, **kw)
    u = cell_axes(pm, ke)[members].reshape(-1, 2)
    radial2 = float(np.mean(((p * u).sum(1) / np.maximum(r, 1e-9)) ** 2))
    pull = np.linalg.norm(gh[members], axis=1)
    cells_c = pm.mean(1)
    lost = float((np.linalg.norm(min_image(cells_c - c, box), axis=1) > R0 + L / 2).sum())
    return dict(time_min=sim.time / 60.0, centre=c.tolist(), R_um=R, r_edge_um=r_edge, n_members=int(members.sum()),
                lost_cells=lost, omega_fit=float(fit["omega"]), fit_r2=float(fit["r2"]),
                edge_speed=v_edge, omega_fit_R=abs(float(fit["omega"])) * R,
                omega_model=mb["omega"], omega_model_free=mfree["omega"], omega_no_pull=m0["omega"],
                omega_fmax=mmax["omega"],
                model_edge_speed=abs(mb["omega"]) * r_edge, model_edge_speed_R=abs(mb["omega"]) * R,
                no_pull_edge_speed=abs(m0["omega"]) * r_edge, fmax_edge_speed=abs(mmax["omega"]) * r_edge,
                torque_identity=tq / mb["drive_torque"] if mb["drive_torque"] else float("nan"),
                omega_profile=prof, rigidity_exponent=rigidity_exponent(r, speed, W, v_b),
                radial_alignment=radial2, mean_pull_pN=float(pull.mean()),
                edge_mean_pull_pN=float(np.linalg.norm(gh[members][np.linalg.norm(pm[members] - c, axis=-1).max(1)
                                                                    >= R - L / 2], axis=1).mean()),
                share_following=float((pull > 0).mean()), share_at_fmax=float((pull >= 0.9 * Fmax).mean()),
                speed_max=float(speed.max()))


def run_case(R_target, kind, rho, k_a, minutes, window_s, samples, threads):
    from taichimyxo.analysis.rigid_body import disk_edge_speed, spiral_prediction
    from taichimyxo.runtime.simulation import Simulation
    sc, R0 = case_scene(R_target, kind, rho, k_a)
    pred = spiral_prediction(sc)
    t0 = time.perf_counter()
    sim = Simulation(sc, threads=threads)
    out = []
    try:
        for t in samples:
            left = int(round(t * 60.0 / sc.dt)) - sim.step_count
            if left > 0:
                sim.run(steps=left)
            out.append(measure(sim, sc, R0, window_s))
    finally:
        sim.close()
    wall = time.perf_counter() - t0
    late = [m for m in out if m["time_min"] >= 1.0 - 1e-9] or out[-1:]
    keys = [k for k, v in late[0].items() if isinstance(v, float) and k != "time_min"]
    mean = {k: float(np.nanmean([m[k] if m[k] is not None else np.nan for m in late])) for k in keys}
    with warnings.catch_warnings():                  # a quarter of R with no particle (inside the spiral's core)
        warnings.simplefilter("ignore", RuntimeWarning)
        mean["omega_profile"] = np.nanmean([m["omega_profile"] for m in late], axis=0).tolist()
    ex = [m["rigidity_exponent"] for m in late if m["rigidity_exponent"] is not None]
    mean["rigidity_exponent"] = float(np.mean(ex)) if ex else None
    disk = disk_edge_speed(kind, sc.v_b_um_per_min, sc.guiding_f_max, sc.engine_force)
    return dict(R_target=R_target, kind=kind, drag_ratio_normal=rho, k_a_N_m=k_a, n_cells=sc.n_cells,
                box_um=sc.box[0], R0_um=R0, dt_ms=sc.dt * 1e3, minutes=minutes, window_s=window_s, wall_s=wall,
                start_prediction=pred, disk_edge_speed=disk, samples=out, late=mean,
                ratio_disk=mean["edge_speed"] / disk, ratio_model=mean["edge_speed"] / mean["model_edge_speed"],
                ratio_omega=mean["omega_fit"] / mean["omega_model"])


def f(v, spec=".3g"):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return format(v, spec)


def write_md(path: Path, res: dict) -> None:
    from taichimyxo.analysis.rigid_body import edge_speed_table
    cases = res["cases"]
    L = ["# Rigid-body check: edge speed of spiral-start aggregates against the rigid-body model", "",
         f"`benchmarks/rigid_body_check.py` ({res['command']}); {res['minutes']:g} simulated min per case, "
         f"velocities over {res['window_s']:g} s windows at t = {', '.join(f'{t:g}' for t in res['samples'])} min, "
         f"table values the mean over t >= 1 min. {res['threads']} thread(s), {res['wall_s'] / 60:.1f} min wall. "
         "Speeds µm/min, omega rad/min (negative: clockwise, the spiral's sense).", "",
         "Model: taichimyxo/analysis/rigid_body.py (the torque balance of S2 Text for chains). (a) ideal disk: "
         "(4/3) v_b = 5.33 for adhesion, (4/3)(1 + F_max/F_e) v_b = 16 for active (its maximum). (b) the torque "
         "balance on the simulator's own configuration at the window's mid time, about the fitted centre, with the "
         "guiding pulls the simulator applied (its per-cell g_head, and adhesion's reactions), edge speed = "
         "|omega_b| x the mean radius of the same edge particles the measurement averages.", "",
         "## Measured / model", "",
         "| R target | cells | kind | k_a | drag ratio | edge speed | (a) disk | meas/(a) | (b) model | meas/(b) | "
         "omega fit | omega (b) | fit/(b) | no-pull (b) | F_max (b) |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in cases:
        m = c["late"]
        L.append(f"| {c['R_target']:g} | {c['n_cells']} | {c['kind']} | {c['k_a_N_m']:g} | {c['drag_ratio_normal']:g}"
                 f" | {f(m['edge_speed'])} | {f(c['disk_edge_speed'])} | {f(c['ratio_disk'], '.2f')} | "
                 f"{f(m['model_edge_speed'])} | {f(c['ratio_model'], '.2f')} | {f(m['omega_fit'])} | "
                 f"{f(m['omega_model'])} | {f(c['ratio_omega'], '.2f')} | {f(m['no_pull_edge_speed'])} | "
                 f"{f(m['fmax_edge_speed'])} |")
    L += ["", "## Which assumption the simulator does not share", "",
          "| R target | kind | k_a | drag | R (µm) | fit R² | omega(r)/omega(b) by quarter of R | rigidity exp. | "
          "(p·u)²/p² | mean pull (pN) | edge cells' pull | at ≥0.9 F_max | torque identity | lost cells |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in cases:
        m = c["late"]
        ob = abs(m["omega_model"])
        prof = " / ".join(f(x / ob, ".2f") for x in m["omega_profile"])
        L.append(f"| {c['R_target']:g} | {c['kind']} | {c['k_a_N_m']:g} | {c['drag_ratio_normal']:g} | "
                 f"{f(m['R_um'])} | {f(m['fit_r2'], '.2f')} | {prof} | {f(m['rigidity_exponent'], '.2f')} | "
                 f"{f(m['radial_alignment'], '.3f')} | {f(m['mean_pull_pN'])} | {f(m['edge_mean_pull_pN'])} | "
                 f"{f(m['share_at_fmax'], '.2f')} | {f(m['torque_identity'], '.3f')} | {f(m['lost_cells'], '.0f')} |")
    L += ["", "## Time course of the edge speed (each sample)", "",
          "| R target | kind | k_a | drag | " + " | ".join(f"t={t:g}" for t in res["samples"]) + " |",
          "|---|---|---|---|" + "---|" * len(res["samples"])]
    for c in cases:
        L.append(f"| {c['R_target']:g} | {c['kind']} | {c['k_a_N_m']:g} | {c['drag_ratio_normal']:g} | " +
                 " | ".join(f"{f(s['edge_speed'])} (b {f(s['model_edge_speed'])})" for s in c["samples"]) + " |")
    L += ["", "## The model alone: rods in polygon rings against the ideal disk", "",
          "Edge speed omega R of rod_rings(R) (straight cells as concentric polygon rings, R = outermost particle + "
          "W/2) over the ideal disk's (4/3) v_b, by drag ratio; the closed form for a uniform disk of tangent rods "
          "(rod_disk_edge_speed) in brackets. Active following at F_max scales both by 3.", "",
          "| R/L | cells | drag 0.5 | drag 1 | drag 2 |", "|---|---|---|---|---|"]
    rows = edge_speed_table()
    for x in sorted({r["R_over_L"] for r in rows}):
        rr = [r for r in rows if r["R_over_L"] == x]
        L.append(f"| {x:g} | {rr[0]['n_cells']} | " + " | ".join(
            f"{r['rings_ratio']:.3f} ({r['closed_ratio']:.3f})"
            for r in sorted(rr, key=lambda r: r["drag_ratio_normal"]))
            + " |")
    if res.get("findings"):
        L += ["", "## Findings", "", *res["findings"]]
    path.write_text("\n".join(L) + "\n")


def findings(cases) -> list[str]:
    """Sentences with the numbers, generated from the results."""
    out = []
    for kind in ("adhesion", "active"):
        cs = [c for c in cases if c["kind"] == kind]
        if not cs:
            continue
        ra = [c["ratio_disk"] for c in cs]
        rb_ = [c["ratio_model"] for c in cs]
        ro = [c["ratio_omega"] for c in cs]
        ev = [c["late"]["edge_speed"] for c in cs]
        out.append(f"- {kind}: edge speed {min(ev):.2f}-{max(ev):.2f} µm/min over {len(cs)} cases; measured/(a) "
                   f"{min(ra):.2f}-{max(ra):.2f}, measured/(b) {min(rb_):.2f}-{max(rb_):.2f}, fitted omega/(b) "
                   f"{min(ro):.2f}-{max(ro):.2f}.")
        if kind == "active":
            mp = [c["late"]["mean_pull_pN"] for c in cs]
            fm = [c["late"]["share_at_fmax"] for c in cs]
            out.append(f"  Pulls: mean {min(mp):.0f}-{max(mp):.0f} pN per cell, share at >= 0.9 F_max "
                       f"{min(fm):.2f}-{max(fm):.2f}: the disk's 4 v_b assumes 200 pN on every cell.")
        tq = [c["late"]["torque_identity"] for c in cs]
        out.append(f"  Torque identity (drag torque of the measured velocities / drive torque): "
                   f"{min(tq):.3f}-{max(tq):.3f}.")
        ex = [c["late"]["rigidity_exponent"] for c in cs if c["late"]["rigidity_exponent"] is not None]
        if ex:
            out.append(f"  Rigidity exponent {min(ex):.2f}-{max(ex):.2f} (1: rigid); outer-quarter omega / model "
                       f"{min(c['late']['omega_profile'][-1] / abs(c['late']['omega_model']) for c in cs):.2f}-"
                       f"{max(c['late']['omega_profile'][-1] / abs(c['late']['omega_model']) for c in cs):.2f}.")
    return out


def main(argv=None, out_dir: str = DEFAULT_OUT) -> int:
    ap = parser(__doc__, "one case (R 5 µm, active, drag 0.5) for 0.5 simulated min")
    ap.set_defaults(out=out_dir)
    ap.add_argument("--minutes", type=float, default=3.0, help="simulated minutes per case (default 3)")
    ap.add_argument("--radii", default="5,10,20", help="target outer radii, µm (default 5,10,20)")
    ap.add_argument("--kinds", default="adhesion,active")
    ap.add_argument("--drags", default="0.5,1,2", help="drag ratios zeta_n / zeta_t (default 0.5,1,2)")
    ap.add_argument("--flexible", action="store_true", help="also flexible cells (1e-17 N·m) at drag ratio 0.5")
    ap.add_argument("--window-s", type=float, default=3.0, help="velocity window, simulated s (default 3)")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    from taichimyxo.runtime import backend
    backend.init("cpu", args.threads)
    backend.restart_between_simulations(True)
    radii = [float(x) for x in args.radii.split(",")]
    kinds = args.kinds.split(",")
    drags = [float(x) for x in args.drags.split(",")]
    minutes = args.minutes
    if args.quick:
        radii, kinds, drags, minutes = [5.0], ["active"], [0.5], 0.5
    samples = sorted({t for t in (0.5, 1.0, 2.0, 3.0, 5.0, 10.0) if t < minutes - 1e-9} | {minutes})
    todo = [(R, k, d, RIGID_KA) for k in kinds for d in drags for R in radii]
    if args.flexible and not args.quick:
        todo += [(R, k, 0.5, FLEXIBLE_KA) for k in kinds for R in radii]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cmd = "python benchmarks/rigid_body_check.py" + ("" if argv is None else " " + " ".join(argv))
    if argv is None:
        cmd = "python benchmarks/rigid_body_check.py " + " ".join(
            a if not a.startswith("/") else Path(a).name for a in sys.argv[1:])
    res = dict(command=cmd.strip(), minutes=minutes, window_s=args.window_s, samples=samples,
               threads=args.threads, cases=[], wall_s=0.0)
    t0 = time.perf_counter()
    for R, kind, rho, k_a in todo:
        c = run_case(R, kind, rho, k_a, minutes, args.window_s, samples, args.threads)
        res["cases"].append(c)
        res["wall_s"] = time.perf_counter() - t0
        m = c["late"]
        print(f"R {R:g} ({c['n_cells']} cells) {kind} k_a {k_a:g} drag {rho:g}: edge {m['edge_speed']:.2f} "
              f"(a) {c['disk_edge_speed']:.2f} (b) {m['model_edge_speed']:.2f}  meas/(a) {c['ratio_disk']:.2f} "
              f"meas/(b) {c['ratio_model']:.2f} omega fit/(b) {c['ratio_omega']:.2f}  pull {m['mean_pull_pN']:.0f} "
              f"pN  [{c['wall_s']:.0f} s]", flush=True)
        res["findings"] = findings(res["cases"])
        (out / "rigid_body_check.json").write_text(json.dumps(res, indent=1))
        write_md(out / "rigid_body_check.md", res)
    print(f"wrote {out / 'rigid_body_check.md'} and .json ({res['wall_s'] / 60:.1f} min)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
