"""Time-step defaults and stability limits per integrator.

The limits come from the package data file stability_limits.json, which a person updates from a stability sweep
(`python benchmarks/stability_sweep.py` writes its measurement to benchmarks-results/stability_limits.json; the
committed one is benchmarks/results/stability.csv): the largest step at which the hard test configurations stayed
within the invariants. Where no measurement covers a scene's stiffnesses, a linear-stability estimate is used:
explicit Euler on the overdamped system is stable for dt < 2 / lambda_max with lambda_max the stiffest rate among
springs (4 k_s / zeta_t), bending (16 k_a / (l0^2 zeta_n)) and contacts (4 k_c / zeta_n, a particle touching up to
~4 segments).

Every function takes the scene (anything with a Scene's attributes); this module imports nothing of scene.py, which
imports it for the default step."""
from __future__ import annotations

import json
from pathlib import Path

from ..io.schema import SceneError

_LIMITS_FILE = Path(__file__).with_name("stability_limits.json")


def measured_limits() -> dict:
    """The shipped measurement: {integrator: {"k_a/k_c": limit_ms}, "defaults": {integrator: {"k_a/k_c": dt_ms}}}."""
    try:
        return json.loads(_LIMITS_FILE.read_text())
    except (OSError, ValueError):
        return {}


def _stiffness_key(scene) -> str:
    return f"{scene.raw['cell']['k_a_N_m']:g}/{scene.raw['collisions']['k_c_N_per_m']:g}"


def estimate_explicit_limit_ms(scene) -> float:
    l0 = scene.rest_length
    lam = max(4 * scene.k_s / scene.zeta_t, 16 * scene.k_a / (l0 * l0 * scene.zeta_n), 4 * scene.k_c / scene.zeta_n)
    return 2.0 / lam * 1e3


def stable_limit_ms(scene) -> float:
    """The largest stable step for the scene's integrator and stiffnesses, ms."""
    table = measured_limits().get(scene.integrator, {})
    key = _stiffness_key(scene)
    if table.get(key, 0) > 0:          # 0: the sweep found no stable step on its grid; use the estimate
        return float(table[key])
    est = estimate_explicit_limit_ms(scene)
    return est if scene.integrator == "explicit" else 4 * est


def default_dt_ms(scene) -> float:
    d = measured_limits().get("defaults", {}).get(scene.integrator)
    if d:
        key = _stiffness_key(scene)
        if key in d:
            return float(d[key])
    return 1.0 if scene.integrator == "explicit" else min(10.0, 0.5 * stable_limit_ms(scene))


def check_step(scene, force: bool = False) -> None:
    if force:
        return
    lim = stable_limit_ms(scene)
    dt_ms = scene.dt * 1e3
    if dt_ms > lim:
        raise SceneError(f"run.dt_ms = {dt_ms:g} exceeds the stability limit {lim:.3g} ms of the {scene.integrator} "
                         f"integrator at {scene.stiffness_label}; use a smaller step or --force")
    longest = scene.longest_step * 1e3           # the step-size controller's longest step (run.dt_ms without it)
    if longest > lim:
        raise SceneError(f"run.step_max_multiple = {scene.step_max_multiple} makes the longest step {longest:g} ms, "
                         f"beyond the stability limit {lim:.3g} ms of the explicit integrator at "
                         f"{scene.stiffness_label}; use a smaller multiple or --force")
