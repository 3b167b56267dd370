"""The scene schema: every scene key with its type, default, allowed values and meaning, and the checks and merges
of raw values against it (taichimyxo.io.scene builds a Scene from these), and a resolved scene written back as TOML.

Convention: every key that carries a unit names it (`k_c_N_per_m`, `f_max_pN`, `dt_ms`). Values in scene files
are in the paper's units (SI or the paper's µm/min, h, min). All defaults live in `SCHEMA` below and nowhere else; a
scene file states only what its paper caption states. Unknown keys, wrong types and out-of-range values are refused
with one line naming the key and what is allowed.
"""
from __future__ import annotations

import json
import math
import tomllib


class SceneError(ValueError):
    """Bad scene input; the message is one line meant for the user."""


# (section, key) -> (type, default, check, doc). check: "pos" (> 0), "nonneg" (>= 0), a tuple of allowed values,
# a (lo, hi) range given as ("range", lo, hi), or None.
_F, _I, _S, _B = float, int, str, bool
SCHEMA: dict[str, dict[str, tuple]] = {
    "scene": {
        "name": (_S, "", None, "short name, e.g. S3"),
        "title": (_S, "", None, "one line for `list`"),
        "paper_figure": (_S, "", None, "figure or video of the paper this reproduces"),
        "caption": (_S, "", None, "what the paper's caption says"),
    },
    "domain": {
        "width_um": (_F, 200.0, "pos", "periodic box width, µm"),
        "height_um": (_F, 200.0, "pos", "periodic box height, µm"),
    },
    "population": {
        "start": (_S, "random", ("random", "aligned", "spiral"), "initial configuration"),
        "density_cells_per_cm2": (_F, 5e6, "pos", "cell density (low 5e6, high 4e7)"),
        "cells": (_I, 0, "nonneg", "number of cells; 0 = density x area"),
        "polarity": (_S, "random", ("random", "same"), "engine directions at start"),
        "aligned_tilt_deg": (_F, 1.0, ("range", 0.0, 30.0), "aligned start: each cell turned about its centre by a "
                             "uniform random angle within +- this, degrees; 0 = exactly parallel rows, which without "
                             "guiding never leave their lanes [decision, docs/model.md]"),
    },
    "cell": {
        "length_um": (_F, 5.0, "pos", "cell length L, µm, read as cell.length_reading says"),
        "length_reading": (_S, "outline", ("outline", "chain"), "cell.length_um is the outline (the chain spans "
                           "L - W, caps included in L) or the chain (the outline is L + W) [decision, docs/model.md]"),
        "width_um": (_F, 0.5, "pos", "cell width W, µm"),
        "particles": (_I, 8, ("range", 3, 64), "particles per cell N"),
        "k_s_N_per_m": (_F, 0.01, "pos", "linear spring stiffness k_s, N/m"),
        "k_a_N_m": (_F, 1e-17, "pos", "angular spring stiffness k_a, N·m (1e-18 very flexible, 1e-17 flexible, "
                                      "1e-16 rigid, 1e-15 very rigid)"),
        "engine_force_pN": (_F, 100.0, "pos", "engine force F_e per cell, pN"),
        "speed_um_per_min": (_F, 4.0, "pos", "free-cell speed v_b, µm/min (sets the drag)"),
        "drag_ratio_normal": (_F, 0.5, "pos", "zeta_n / zeta_t [decision, docs/model.md]"),
    },
    "collisions": {
        "k_c_N_per_m": (_F, 0.01, "pos", "collision stiffness k_c, N/m (low density 0.01, high 0.002)"),
    },
    "guiding": {
        "kind": (_S, "none", ("none", "passive", "active", "adhesion"), "short-range head-to-tail guiding"),
        "f_max_pN": (_F, 200.0, "pos", "maximum guiding force F_max^g, pN"),
        "range_um": (_F, 0.25, "pos", "guiding range d_g (gap beyond W), µm"),
        "distance": (_S, "segments", ("segments", "particles"), "head-tail distance: between segments or particles"),
        "self": (_B, True, None, "a cell may follow its own tail"),
        "pull_on": (_S, "head_particle", ("head_particle", "head_segment"), "where the follower's pull acts: its head "
                    "particle, or shared equally by its head segment's two particles [decision, docs/model.md]"),
        "reaction_on": (_S, "tail_particle", ("tail_particle", "tail_segment"), "adhesion: where the reaction acts "
                        "on the leader: its tail particle, or shared by its tail segment's two particles [decision]"),
    },
    "slime": {
        "enabled": (_B, False, None, "long-range guiding by slime trails"),
        "grid_um": (_F, 0.25, "pos", "slime grid element side, µm"),
        "f_max_pN": (_F, 200.0, "pos", "slime guiding force F_max^s, pN"),
    },
    "reversals": {
        "enabled": (_B, False, None, "cells reverse their engine direction periodically"),
        "period_min": (_F, 10.0, "pos", "mean reversal period T_R, min"),
        "period_sd_fraction": (_F, 0.24, "nonneg", "SD of the period as a fraction of T_R"),
        "min_period_fraction": (_F, 0.1, "pos", "periods are truncated below this fraction of T_R"),
        "suppression": (_B, False, None, "skip reversals during head-to-tail interactions"),
        "suppression_contacts": (_S, "head_or_tail", ("head_or_tail", "head"), "suppression: a cell's reversal is "
                                 "held while its head follows a tail or its tail is followed (head_or_tail), or only "
                                 "while its head follows (head) [decision, docs/model.md]"),
        "suppressed_wait": (_S, "period", ("period", "contact_end"), "suppression: a held reversal waits a new period "
                            "(its clock restarts) or only until the contact ends [decision, docs/model.md]"),
    },
    "run": {
        "hours": (_F, 6.0, "pos", "simulated time, h"),
        "dt_ms": (_F, 0.0, "nonneg", "time step, ms; 0 = the integrator's default from the accuracy study"),
        "integrator": (_S, "explicit", ("explicit", "imex", "imex-explicit"), "explicit: the paper's overdamped "
                       "Euler step; imex: springs, bending and contacts linearly implicit, contacts coupled by CG; "
                       "imex-explicit: springs and bending implicit, contacts explicit"),
        "precision": (_S, "mixed", ("f32", "f64", "mixed"), "f32, f64, or mixed (f64 positions, f32 forces)"),
        "seed": (_I, 1, "nonneg", "random seed"),
        "mass_pg": (_F, 0.0, "nonneg", "particle mass for the semi-implicit Euler step, pg; 0 = overdamped"),
        "step_control": (_S, "fixed", ("fixed", "error"), "fixed: every step is run.dt_ms; error: each step covers "
                         "1 to run.step_max_multiple of them, chosen from the estimated local error (explicit only; "
                         "docs/accuracy.md)"),
        "step_tolerance_um": (_F, 1e-4, "pos", "step_control = error: the largest local error of a step, µm "
                              "(1/2 h max |v_n - v_n-1| over particles)"),
        "step_max_multiple": (_I, 2, ("range", 1, 64), "step_control = error: the longest step, in run.dt_ms"),
        "skin_um": (_F, 0.1, "pos", "neighbour-list skin, µm (the fastest measured, docs/performance.md)"),
        "max_neighbours": (_I, 0, "nonneg", "neighbour-list capacity per segment; 0 = from density"),
        "speed_window_s": (_F, 1.0, "pos", "window over which displayed speeds are averaged, s"),
    },
    "output": {
        "frame_interval_min": (_F, 1.0, "pos", "simulated minutes between movie frames"),
        "trajectory_interval_min": (_F, 0.0, "nonneg", "simulated minutes between trajectory frames; "
                                    "0 = output.frame_interval_min"),
        "color": (_S, "speed", ("speed", "strain", "identity", "polarity", "orientation"),
                  "what the movie colours by: segment speed or strain; cell identity, polarity or axis angle"),
        "color_min": (_F, 0.0, "nonneg", "lower end of the colour scale for speed (µm/min) or strain (J); "
                      "color_min = color_max = 0: the colouring's default range (0-16 µm/min, 1e-21-1e-17 J)"),
        "color_max": (_F, 0.0, "nonneg", "upper end of the colour scale for speed (µm/min) or strain (J)"),
        "video_width": (_I, 1920, ("range", 64, 7680), "movie width, px"),
        "video_height": (_I, 1080, ("range", 64, 4320), "movie height, px"),
        "fps": (_F, 10.0, "pos", "movie frames per second"),
        "strain": (_B, False, None, "log per-segment strain energy in the trajectory"),
        "movie": (_B, True, None, "write an MP4"),
    },
    "preview": {
        "scale": (_F, 0.25, ("range", 0.01, 1.0), "--preview: box side scaled by this (cells scale with area)"),
        "hours": (_F, 0.1, "pos", "--preview: simulated time, h"),
        "frame_interval_min": (_F, 0.05, "pos", "--preview: minutes between frames (3 s: an aggregate turns a few "
                                                "degrees a frame; a 6 min preview is a 12 s movie at 10 fps)"),
    },
}

# Keys added after runs were keyed by a hash of their scene's values (Scene.trajectory_values), each with the value
# that reproduces the behaviour before it: at that value a key is left out of the hash, so every earlier run, sweep
# point and checkpoint keeps its key. A key whose default later changes still hashes at every other value.
ADDED_KEYS: dict[str, object] = {
    "cell.length_reading": "outline", "guiding.pull_on": "head_particle", "guiding.reaction_on": "tail_particle",
    "reversals.suppression_contacts": "head_or_tail", "reversals.suppressed_wait": "period",
}

# The densest random start placed reliably and in bounded time (placement.py, "Random sequential placement": above
# 0.40 the tries per cell climb from hundreds to thousands, and past 0.44 placement stalls).
RANDOM_MAX_AREA_FRACTION = 0.40

# the stiffness names the paper uses
STIFFNESS_NAMES = {1e-18: "very flexible", 1e-17: "flexible", 1e-16: "rigid", 1e-15: "very rigid"}


def did_you_mean(word: str, choices) -> str:
    """' (did you mean S3?)' for a near miss (case ignored), else ''."""
    import difflib
    choices = list(choices)
    folded = {c.lower(): c for c in choices}
    if word.lower() in folded:
        return f" (did you mean {folded[word.lower()]}?)"
    close = difflib.get_close_matches(word.lower(), list(folded), n=1, cutoff=0.6)
    return f" (did you mean {folded[close[0]]}?)" if close else ""


def all_keys() -> list[str]:
    return [f"{sec}.{k}" for sec, keys in SCHEMA.items() for k in keys]


def allowed(check) -> str:
    """What a key's check allows, in words ('' when any value of its type goes)."""
    if check == "pos":
        return "> 0"
    if check == "nonneg":
        return ">= 0"
    if isinstance(check, tuple) and check and check[0] == "range":
        return f"{check[1]:g} to {check[2]:g}"
    if isinstance(check, tuple):
        return " | ".join(map(str, check))
    return ""


def defaults() -> dict:
    return {sec: {k: v[1] for k, v in keys.items()} for sec, keys in SCHEMA.items()}


def _check_value(sec: str, key: str, val):
    typ, _, check, _ = SCHEMA[sec][key]
    name = f"{sec}.{key}"
    if typ is _F:
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            raise SceneError(f"{name} = {val!r}: expected a number")
        val = float(val)
        if not math.isfinite(val):
            raise SceneError(f"{name} = {val!r}: expected a finite number")
    elif typ is _I:
        if isinstance(val, bool) or not (isinstance(val, int) or (isinstance(val, float) and val.is_integer())):
            raise SceneError(f"{name} = {val!r}: expected an integer")
        val = int(val)
    elif typ is _B:
        if not isinstance(val, bool):
            raise SceneError(f"{name} = {val!r}: expected true or false")
    elif typ is _S:
        if not isinstance(val, str):
            raise SceneError(f"{name} = {val!r}: expected a string")
    if check == "pos" and not val > 0:
        raise SceneError(f"{name} = {val!r}: must be positive")
    if check == "nonneg" and not val >= 0:
        raise SceneError(f"{name} = {val!r}: must be zero or positive")
    if isinstance(check, tuple) and check and check[0] == "range":
        if not (check[1] <= val <= check[2]):
            raise SceneError(f"{name} = {val!r}: must be between {check[1]} and {check[2]}")
    elif isinstance(check, tuple) and val not in check:
        raise SceneError(f"{name} = {val!r}: allowed values are {', '.join(map(str, check))}"
                         f"{did_you_mean(str(val), map(str, check))}")
    return val


def merge(base: dict, over: dict, where: str) -> None:
    for sec, body in over.items():
        if sec not in SCHEMA:
            raise SceneError(f"{where}: unknown section [{sec}]{did_you_mean(sec, SCHEMA)}; "
                             f"allowed: {', '.join(SCHEMA)}")
        if not isinstance(body, dict):
            raise SceneError(f"{where}: [{sec}] must be a table")
        for key, val in body.items():
            if key not in SCHEMA[sec]:
                raise SceneError(f"{where}: unknown key {sec}.{key}{did_you_mean(key, SCHEMA[sec])}; "
                                 f"allowed in [{sec}]: {', '.join(SCHEMA[sec])}")
            base[sec][key] = _check_value(sec, key, val)


def parse_set(items: list[str]) -> dict:
    """--set KEY=VALUE (dotted key, TOML value; bare words are taken as strings) -> nested dict."""
    out: dict = {}
    for item in items or []:
        if "=" not in item:
            raise SceneError(f"--set {item!r}: expected KEY=VALUE, e.g. --set guiding.kind=active")
        key, raw = item.split("=", 1)
        key = key.strip()
        if key.count(".") != 1:
            raise SceneError(f"--set {key!r}: expected a dotted key SECTION.KEY, e.g. cell.k_a_N_m")
        sec, k = key.split(".")
        if sec not in SCHEMA or k not in SCHEMA[sec]:
            raise SceneError(f"--set {key}: unknown key{did_you_mean(key, all_keys())}; "
                             "see `python -m taichimyxo keys`")
        try:
            val = tomllib.loads(f"v = {raw.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            val = raw.strip()
        out.setdefault(sec, {})[k] = val
    return out


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    return json.dumps(v, ensure_ascii=False)      # a JSON string is a valid TOML basic string


def to_toml(scene) -> str:
    """The resolved scene as a TOML file: every key with its value (defaults included, after --set and --preview),
    its meaning as a comment. Loading the text back gives the same scene (--preview's scaling already applied)."""
    lines = [f"# {scene.name}: resolved from {scene.source or 'defaults'}"]
    if scene.preview_scaled:
        lines.append("# --preview scaled " + ", ".join(f"{k} (from {v!r})" for k, v in scene.preview_scaled.items()))
    notes = {("run", "dt_ms"): f"resolves to {scene.dt * 1e3:g} ms",
             ("population", "cells"): f"resolves to {scene.n_cells} cells",
             ("output", "trajectory_interval_min"): f"resolves to "
             f"{scene.trajectory_every_steps * scene.dt / 60:g} min"}
    for sec, keys in SCHEMA.items():
        lines += ["", f"[{sec}]"]
        width = max(len(f"{k} = {toml_value(scene.raw[sec][k])}") for k in keys)
        for k, (_, _, _, doc) in keys.items():
            entry = f"{k} = {toml_value(scene.raw[sec][k])}"
            note = f"{doc}" + (f"; {notes[(sec, k)]}" if (sec, k) in notes and scene.raw[sec][k] == 0 else "")
            lines.append(f"{entry:<{width}}  # {note}")
    return "\n".join(lines) + "\n"


def check_scene(scene) -> None:
    """Cross-key checks of a resolved Scene (single keys were checked on merge); SceneError names the keys."""
    Lx, Ly = scene.box
    if min(Lx, Ly) < 2 * scene.length:
        raise SceneError(f"domain.width_um x domain.height_um = {Lx:g} x {Ly:g} µm: each side must be at least two "
                         f"cell lengths (2 x cell.length_um = {2 * scene.length:g} µm)")
    if scene.width >= scene.length:
        raise SceneError(f"cell.width_um = {scene.width:g} must be smaller than cell.length_um = {scene.length:g}")
    if scene.n_cells < 1:
        raise SceneError(f"population.density_cells_per_cm2 = {scene.raw['population']['density_cells_per_cm2']:g} "
                         f"(population.cells = {scene.raw['population']['cells']}) gives {scene.n_cells} cells in "
                         f"{Lx:g} x {Ly:g} µm; need at least 1")
    af = scene.area_fraction
    limit = {"random": RANDOM_MAX_AREA_FRACTION, "aligned": 1.0 + 1e-9, "spiral": 0.9}[scene.start]
    if af > limit:
        c = scene.raw["population"]["cells"]
        given = (f"population.cells = {c}" if c else
                 f"population.density_cells_per_cm2 = {scene.raw['population']['density_cells_per_cm2']:g} "
                 f"({scene.n_cells} cells in {Lx:g} x {Ly:g} µm)")
        raise SceneError(f"{given} covers {af:.2f} of the area; the {scene.start!r} start can place at most "
                         f"{limit:.2f}")
    if scene.start == "spiral":
        from ..physics.placement import spiral_capacity
        cap = spiral_capacity(scene)
        if scene.n_cells > cap:
            raise SceneError(f"population: {scene.n_cells} cells do not fit on a spiral in {Lx:g} x {Ly:g} µm "
                             f"(at most {cap})")
    if scene.dt <= 0:
        raise SceneError("run.dt_ms resolved to zero")
    if scene.step_control == "error" and scene.integrator != "explicit":
        raise SceneError(f"run.step_control = 'error' needs run.integrator = 'explicit' (not "
                         f"{scene.integrator!r}): its error estimate is the explicit step's")
    if scene.hours * 3600 < scene.dt:
        raise SceneError(f"run.hours = {scene.hours:g} is shorter than one step (run.dt_ms = {scene.dt * 1e3:g})")
    o = scene.raw["output"]
    if o["color_min"] or o["color_max"]:
        if o["color"] not in ("speed", "strain"):
            raise SceneError(f"output.color_min/color_max set a range for speed or strain; output.color = "
                             f"{o['color']!r} has no range")
        if not o["color_max"] > o["color_min"]:
            raise SceneError(f"output.color_max = {o['color_max']:g} must be above output.color_min = "
                             f"{o['color_min']:g}")
        if o["color"] == "strain" and o["color_min"] <= 0:
            raise SceneError("output.color_min must be positive for strain (a log scale), e.g. 1e-21")
