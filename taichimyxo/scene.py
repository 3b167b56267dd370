"""Scenes: TOML files validated into a Scene, with units converted once, here.

Convention: every key that carries a unit names it (`k_c_N_per_m`, `f_max_pN`, `dt_ms`). Values in scene files
are in the paper's units (SI or the paper's µm/min, h, min); `Scene` exposes internal units (µm, s, pN).
All defaults live in `SCHEMA` below and nowhere else; a scene file states only what its paper caption states.
Unknown keys, wrong types and out-of-range values are refused with one line naming the key and what is allowed.
"""
from __future__ import annotations

import copy
import json
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path


def _scenes_dir() -> Path:
    """Where the scene files are: inside the package in an installed wheel (pyproject.toml maps scenes/ to
    taichimyxo/scenes), at the top of the clone otherwise (also for an editable install)."""
    here = Path(__file__).resolve().parent
    for d in (here / "scenes", here.parent / "scenes"):
        if d.is_dir() and any(d.glob("*.toml")):
            return d
    return here / "scenes"


SCENES_DIR = _scenes_dir()

# The densest random start placed reliably and in bounded time (init.py, "Random sequential placement": above
# 0.40 the tries per cell climb from hundreds to thousands, and past 0.44 placement stalls).
RANDOM_MAX_AREA_FRACTION = 0.40


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
    },
    "cell": {
        "length_um": (_F, 5.0, "pos", "outline length L including round caps, µm"),
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
    },
    "run": {
        "hours": (_F, 6.0, "pos", "simulated time, h"),
        "dt_ms": (_F, 0.0, "nonneg", "time step, ms; 0 = the integrator's default from the accuracy study"),
        "integrator": (_S, "explicit", ("explicit", "imex"), "explicit: the paper's overdamped Euler step; "
                       "imex: springs, bending and contacts linearly implicit, contacts coupled by CG"),
        "precision": (_S, "mixed", ("f32", "f64", "mixed"), "f32, f64, or mixed (f64 positions, f32 forces)"),
        "seed": (_I, 1, "nonneg", "random seed"),
        "mass_pg": (_F, 0.0, "nonneg", "particle mass for the semi-implicit Euler step, pg; 0 = overdamped"),
        "skin_um": (_F, 0.3, "pos", "neighbour-list skin, µm"),
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
        "frame_interval_min": (_F, 0.25, "pos", "--preview: minutes between frames"),
    },
}

# the stiffness names the paper uses
STIFFNESS_NAMES = {1e-18: "very flexible", 1e-17: "flexible", 1e-16: "rigid", 1e-15: "very rigid"}


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
        raise SceneError(f"{name} = {val!r}: allowed values are {', '.join(map(str, check))}")
    return val


def _merge(base: dict, over: dict, where: str) -> None:
    for sec, body in over.items():
        if sec not in SCHEMA:
            raise SceneError(f"{where}: unknown section [{sec}]; allowed: {', '.join(SCHEMA)}")
        if not isinstance(body, dict):
            raise SceneError(f"{where}: [{sec}] must be a table")
        for key, val in body.items():
            if key not in SCHEMA[sec]:
                raise SceneError(f"{where}: unknown key {sec}.{key}; allowed in [{sec}]: {', '.join(SCHEMA[sec])}")
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
            raise SceneError(f"--set {key}: unknown key; see `python -m taichimyxo keys`")
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


def to_toml(scene: "Scene") -> str:
    """The resolved scene as a TOML file: every key with its value (defaults included, after --set and --preview),
    its meaning as a comment. Loading the text back gives the same scene (--preview's scaling already applied)."""
    lines = [f"# {scene.name}: resolved from {scene.source or 'defaults'}"]
    if scene.preview_scaled:
        lines.append("# --preview scaled " + ", ".join(f"{k} (from {v!r})" for k, v in scene.preview_scaled.items()))
    notes = {("run", "dt_ms"): f"resolves to {scene.dt * 1e3:g} ms",
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


def available_scenes() -> list[str]:
    if not SCENES_DIR.is_dir():
        return []
    return sorted((p.stem for p in SCENES_DIR.glob("*.toml")), key=_scene_sort_key)


def _scene_sort_key(name: str):
    import re
    m = re.match(r"S(\d+)(.*)", name)
    return (0, int(m.group(1)), m.group(2)) if m else (1, 0, name)


def resolve_path(name_or_path: str) -> Path:
    p = Path(name_or_path)
    if p.suffix == ".toml" or os.sep in name_or_path:
        if not p.is_file():
            raise SceneError(f"scene file {name_or_path} not found")
        return p
    cand = SCENES_DIR / f"{name_or_path}.toml"
    if not cand.is_file():
        raise SceneError(f"unknown scene {name_or_path!r}; available: {', '.join(available_scenes())}")
    return cand


@dataclass(frozen=True)
class Scene:
    """A validated scene. `raw` holds the values in scene-file units; properties give internal units."""
    raw: dict
    source: str = ""
    # "section.key" -> the value before --preview scaled it (values the user set are never scaled)
    preview_scaled: dict = field(default_factory=dict)

    # ---- construction
    @classmethod
    def load(cls, name_or_path: str, overrides: dict | None = None, preview: bool = False) -> "Scene":
        path = resolve_path(name_or_path)
        try:
            data = tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as e:
            raise SceneError(f"{path}: malformed TOML: {e}") from None
        return cls.from_dict(data, overrides, preview, where=str(path), default_name=path.stem)

    @classmethod
    def from_dict(cls, data: dict, overrides: dict | None = None, preview: bool = False, where: str = "scene",
                  default_name: str = "") -> "Scene":
        """preview: the scene's box side scaled by preview.scale (cells with the area), its duration capped at
        preview.hours, frames every preview.frame_interval_min, a small movie; a value given in `overrides` (--set
        and the command line's options) is the user's and is never rescaled."""
        raw = defaults()
        _merge(raw, data, where)
        if overrides:
            _merge(raw, overrides, "--set")
        if not raw["scene"]["name"]:
            raw["scene"]["name"] = default_name or "scene"
        scaled = {}
        if preview:
            user = {(sec, k) for sec, body in (overrides or {}).items() for k in body}

            def scale(sec, key, value):
                if (sec, key) not in user and raw[sec][key] != value:
                    scaled[f"{sec}.{key}"] = raw[sec][key]
                    raw[sec][key] = value

            s = raw["preview"]["scale"]
            scale("domain", "width_um", raw["domain"]["width_um"] * s)
            scale("domain", "height_um", raw["domain"]["height_um"] * s)
            if raw["population"]["cells"]:
                scale("population", "cells", max(1, round(raw["population"]["cells"] * s * s)))
            scale("run", "hours", min(raw["run"]["hours"], raw["preview"]["hours"]))
            scale("output", "frame_interval_min", raw["preview"]["frame_interval_min"])
            scale("output", "video_width", min(raw["output"]["video_width"], 640))
            scale("output", "video_height", min(raw["output"]["video_height"], 480))
            raw["scene"]["name"] += "-preview" if not raw["scene"]["name"].endswith("-preview") else ""
        sc = cls(raw=raw, source=where, preview_scaled=scaled)
        sc.validate()
        return sc

    def with_overrides(self, overrides: dict) -> "Scene":
        raw = copy.deepcopy(self.raw)
        _merge(raw, overrides, "override")
        scaled = {k: v for k, v in self.preview_scaled.items()
                  if k.split(".")[1] not in overrides.get(k.split(".")[0], {})}
        sc = Scene(raw=raw, source=self.source, preview_scaled=scaled)
        sc.validate()
        return sc

    def preview_note(self) -> str:
        """'' or, for a --preview scene, what --preview scaled and from what, to append to an error message."""
        # the sizes an error can be about (the movie's size and frame interval never make a scene invalid)
        keys = [k for k in self.preview_scaled if k.split(".")[0] in ("domain", "population", "run")]
        if not keys:
            return ""
        items = ", ".join(f"{k} from {self.preview_scaled[k]:g} to {self.raw[k.split('.')[0]][k.split('.')[1]]:g}"
                          for k in keys)
        return f" (--preview scaled {items}; values given with --set are not scaled)"

    def validate(self) -> None:
        """Cross-key checks (single keys were checked on merge); errors say what --preview scaled."""
        try:
            self._validate()
        except SceneError as e:
            raise SceneError(f"{e}{self.preview_note()}") from None

    def _validate(self) -> None:
        Lx, Ly = self.box
        if min(Lx, Ly) < 2 * self.length:
            raise SceneError(f"domain.width_um x domain.height_um = {Lx:g} x {Ly:g} µm: each side must be at least two "
                             f"cell lengths (2 x cell.length_um = {2 * self.length:g} µm)")
        if self.width >= self.length:
            raise SceneError(f"cell.width_um = {self.width:g} must be smaller than cell.length_um = {self.length:g}")
        if self.n_cells < 1:
            raise SceneError(f"population gives {self.n_cells} cells in {Lx:g} x {Ly:g} µm; need at least 1")
        af = self.area_fraction
        limit = {"random": RANDOM_MAX_AREA_FRACTION, "aligned": 1.0 + 1e-9, "spiral": 0.9}[self.start]
        if af > limit:
            c = self.raw["population"]["cells"]
            given = (f"population.cells = {c}" if c else
                     f"population.density_cells_per_cm2 = {self.raw['population']['density_cells_per_cm2']:g} "
                     f"({self.n_cells} cells in {Lx:g} x {Ly:g} µm)")
            raise SceneError(f"{given} covers {af:.2f} of the area; the {self.start!r} start can place at most "
                             f"{limit:.2f}")
        if self.start == "spiral":
            from .init import spiral_capacity
            cap = spiral_capacity(self)
            if self.n_cells > cap:
                raise SceneError(f"population: {self.n_cells} cells do not fit on a spiral in {Lx:g} x {Ly:g} µm "
                                 f"(at most {cap})")
        if self.dt <= 0:
            raise SceneError("run.dt_ms resolved to zero")
        if self.hours * 3600 < self.dt:
            raise SceneError(f"run.hours = {self.hours:g} is shorter than one step")
        o = self.raw["output"]
        if o["color_min"] or o["color_max"]:
            if o["color"] not in ("speed", "strain"):
                raise SceneError(f"output.color_min/color_max set a range for speed or strain; output.color = "
                                 f"{o['color']!r} has no range")
            if not o["color_max"] > o["color_min"]:
                raise SceneError(f"output.color_max = {o['color_max']:g} must be above output.color_min = "
                                 f"{o['color_min']:g}")
            if o["color"] == "strain" and o["color_min"] <= 0:
                raise SceneError("output.color_min must be positive for strain (a log scale), e.g. 1e-21")

    @property
    def color_range(self) -> dict:
        """Render options for the movie's colour range (empty: the colouring's default)."""
        o = self.raw["output"]
        return {"vmin": o["color_min"], "vmax": o["color_max"]} if (o["color_min"] or o["color_max"]) else {}

    # ---- names and bookkeeping
    @property
    def name(self) -> str:
        return self.raw["scene"]["name"]

    def to_dict(self) -> dict:
        return copy.deepcopy(self.raw)

    def fingerprint(self, exclude=("output", "scene", "preview")) -> str:
        """Hash of everything that changes the simulated trajectory (not the output settings)."""
        import hashlib
        d = {k: v for k, v in self.raw.items() if k not in exclude}
        d["run"] = {k: v for k, v in d["run"].items() if k != "hours"}
        d["_dt"] = self.dt
        return hashlib.sha1(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]

    # ---- internal units (µm, s, pN)
    @property
    def box(self) -> tuple[float, float]:
        return (self.raw["domain"]["width_um"], self.raw["domain"]["height_um"])

    @property
    def start(self) -> str:
        return self.raw["population"]["start"]

    @property
    def n_cells(self) -> int:
        c = self.raw["population"]["cells"]
        if c:
            return int(c)
        Lx, Ly = self.box
        per_um2 = self.raw["population"]["density_cells_per_cm2"] * 1e-8
        return int(round(per_um2 * Lx * Ly))

    @property
    def area_fraction(self) -> float:
        """n L W / box area: 0.125 at the paper's low density, 1.0 at its high density."""
        Lx, Ly = self.box
        return self.n_cells * self.length * self.width / (Lx * Ly)

    @property
    def N(self) -> int:
        return self.raw["cell"]["particles"]

    @property
    def length(self) -> float:
        return self.raw["cell"]["length_um"]

    @property
    def width(self) -> float:
        return self.raw["cell"]["width_um"]

    @property
    def rest_length(self) -> float:
        """l0: the chain spans L - W [decision, docs/model.md]."""
        return (self.length - self.width) / (self.N - 1)

    @property
    def k_s(self) -> float:      # N/m -> pN/µm: x 1e6
        return self.raw["cell"]["k_s_N_per_m"] * 1e6

    @property
    def k_a(self) -> float:      # N·m -> pN·µm: x 1e18
        return self.raw["cell"]["k_a_N_m"] * 1e18

    @property
    def k_c(self) -> float:
        return self.raw["collisions"]["k_c_N_per_m"] * 1e6

    @property
    def engine_force(self) -> float:
        return self.raw["cell"]["engine_force_pN"]

    @property
    def v_b(self) -> float:      # µm/min -> µm/s
        return self.raw["cell"]["speed_um_per_min"] / 60.0

    @property
    def zeta_t(self) -> float:
        """Tangential drag per particle, pN·s/µm: a free straight cell moves at v_b."""
        return (self.engine_force / self.N) / self.v_b

    @property
    def zeta_n(self) -> float:
        return self.zeta_t * self.raw["cell"]["drag_ratio_normal"]

    @property
    def guiding(self) -> str:
        return self.raw["guiding"]["kind"]

    @property
    def k_g(self) -> float:
        return self.raw["guiding"]["f_max_pN"] / self.raw["guiding"]["range_um"]

    @property
    def slime(self) -> bool:
        return self.raw["slime"]["enabled"]

    @property
    def reversals(self) -> bool:
        return self.raw["reversals"]["enabled"]

    @property
    def suppression(self) -> bool:
        return self.reversals and self.raw["reversals"]["suppression"]

    @property
    def integrator(self) -> str:
        return self.raw["run"]["integrator"]

    @property
    def precision(self) -> str:
        return self.raw["run"]["precision"]

    @property
    def dt(self) -> float:
        """Time step in s; 0 in the file means the integrator's default (see stability.py)."""
        ms = self.raw["run"]["dt_ms"]
        if ms > 0:
            return ms * 1e-3
        from .stability import default_dt_ms
        return default_dt_ms(self) * 1e-3

    @property
    def hours(self) -> float:
        return self.raw["run"]["hours"]

    @property
    def steps(self) -> int:
        return int(round(self.hours * 3600.0 / self.dt))

    @property
    def seed(self) -> int:
        return self.raw["run"]["seed"]

    @property
    def frame_every_steps(self) -> int:
        return max(1, int(round(self.raw["output"]["frame_interval_min"] * 60.0 / self.dt)))

    @property
    def trajectory_every_steps(self) -> int:
        """Steps between trajectory frames (output.trajectory_interval_min; 0: the movie's frame interval)."""
        m = self.raw["output"]["trajectory_interval_min"]
        return self.frame_every_steps if m == 0 else max(1, int(round(m * 60.0 / self.dt)))

    @property
    def strain(self) -> bool:
        """Strain energy is computed only when the movie or the trajectory asks for it."""
        return self.raw["output"]["strain"] or self.raw["output"]["color"] == "strain"
