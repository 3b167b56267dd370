"""Scenes: TOML files validated into a Scene, with units converted once, here.

Convention: every key that carries a unit names it (`k_c_N_per_m`, `f_max_pN`, `dt_ms`). Values in scene files
are in the paper's units (SI or the paper's µm/min, h, min); `Scene` exposes internal units (µm, s, pN).
All defaults live in `SCHEMA` (taichimyxo/io/schema.py) and nowhere else; a scene file states only what its paper
caption states.
Unknown keys, wrong types and out-of-range values are refused with one line naming the key and what is allowed.
"""
from __future__ import annotations

import copy
import json
import tomllib
from dataclasses import dataclass, field

from ..physics.stability import default_dt_ms
from .catalogue import SCENES_DIR, available_scenes, resolve_path  # noqa: F401  (re-exported)

# the schema (every key, its default and check) and its errors; re-exported: `from taichimyxo.io.scene import SCHEMA`
from .schema import (  # noqa: F401
    ADDED_KEYS,
    RANDOM_MAX_AREA_FRACTION,
    SCHEMA,
    STIFFNESS_NAMES,
    SceneError,
    check_scene,
    defaults,
    merge,
    parse_set,
    to_toml,
    toml_value,
)


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
        merge(raw, data, where)
        if overrides:
            merge(raw, overrides, "--set")
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
            scale("output", "video_width", min(raw["output"]["video_width"], 1280))      # a square box: 722 x 840
            scale("output", "video_height", min(raw["output"]["video_height"], 840))
            raw["scene"]["name"] += "-preview" if not raw["scene"]["name"].endswith("-preview") else ""
        sc = cls(raw=raw, source=where, preview_scaled=scaled)
        sc.validate()
        return sc

    def resized(self, width_um: float, height_um: float) -> dict:
        """Overrides for a width_um x height_um box at this density (an explicit cell count with the area): sweeps,
        figures, videos and benchmarks size boxes this one way, so the same box is the same scene."""
        (w0, h0), cells = self.box, self.raw["population"]["cells"]
        out = {"domain": {"width_um": float(width_um), "height_um": float(height_um)}}
        return {**out, "population": {"cells": max(1, round(cells * (width_um * height_um) / (w0 * h0)))}} \
            if cells else out

    def with_overrides(self, overrides: dict) -> "Scene":
        raw = copy.deepcopy(self.raw)
        merge(raw, overrides, "override")
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
            check_scene(self)
        except SceneError as e:
            raise SceneError(f"{e}{self.preview_note()}") from None

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

    def trajectory_values(self, exclude=("output", "scene", "preview")) -> dict:
        """The resolved values that can change the simulated trajectory: the sections not excluded, less the keys
        that the scene's start does not read (so adding such a key leaves other scenes' hashes as they were)."""
        d = {k: (copy.deepcopy(v) if isinstance(v, dict) else v) for k, v in self.raw.items() if k not in exclude}
        if self.start != "aligned" and "population" in d:
            d["population"].pop("aligned_tilt_deg", None)
        for dotted, before in ADDED_KEYS.items():
            sec, key = dotted.split(".")
            if sec in d and key in d[sec] and d[sec][key] == before:
                del d[sec][key]
        return d

    def fingerprint(self, exclude=("output", "scene", "preview")) -> str:
        """Hash of everything that changes the simulated trajectory (not the output settings)."""
        import hashlib
        d = self.trajectory_values(exclude)
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
        c, (Lx, Ly) = self.raw["population"]["cells"], self.box
        return int(c) if c else int(round(self.raw["population"]["density_cells_per_cm2"] * 1e-8 * Lx * Ly))

    @property
    def area_fraction(self) -> float:
        """n L W / box area: 0.125 at the paper's low density, 1.0 at its high density."""
        return self.n_cells * self.length * self.width / (self.box[0] * self.box[1])

    @property
    def N(self) -> int:
        return self.raw["cell"]["particles"]

    @property
    def length(self) -> float:
        """The outline L, caps included (cell.length_um, + W where cell.length_reading names the chain)."""
        return self.raw["cell"]["length_um"] + (0.0 if self.raw["cell"]["length_reading"] == "outline" else self.width)

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
    def title(self) -> str:
        return self.raw["scene"]["title"]

    @property
    def paper_figure(self) -> str:
        return self.raw["scene"]["paper_figure"]

    @property
    def polarity(self) -> str:
        return self.raw["population"]["polarity"]

    @property
    def aligned_tilt_deg(self) -> float:
        return self.raw["population"]["aligned_tilt_deg"]

    @property
    def v_b_um_per_min(self) -> float:
        """Free-cell speed v_b in the paper's unit, µm/min (what speeds are shown in)."""
        return self.raw["cell"]["speed_um_per_min"]

    @property
    def stiffness_label(self) -> str:
        """k_a and k_c as the scene gives them: "k_a = 1e-17 N·m, k_c = 0.01 N/m"."""
        return f"k_a = {self.raw['cell']['k_a_N_m']:g} N·m, k_c = {self.raw['collisions']['k_c_N_per_m']:g} N/m"

    @property
    def movie(self) -> bool:
        return self.raw["output"]["movie"]

    @property
    def color(self) -> str:
        """The movie's colouring (output.color)."""
        return self.raw["output"]["color"]

    @property
    def video_size(self) -> tuple[int, int]:
        return (self.raw["output"]["video_width"], self.raw["output"]["video_height"])

    @property
    def fps(self) -> float:
        return self.raw["output"]["fps"]

    @property
    def guiding_f_max(self) -> float:
        """Maximum guiding force F_max^g, pN."""
        return self.raw["guiding"]["f_max_pN"]

    @property
    def guiding_range(self) -> float:
        """Guiding range d_g (gap beyond W), µm."""
        return self.raw["guiding"]["range_um"]

    @property
    def guiding_by_particles(self) -> bool:
        """Head-to-tail distance between particles (else between segments)."""
        return self.raw["guiding"]["distance"] == "particles"

    @property
    def guiding_self(self) -> bool:
        return self.raw["guiding"]["self"]

    # the readings the decision study compares (docs/decisions.md), as the terms ask for them
    @property
    def guiding_pull_shared(self) -> bool:
        return self.raw["guiding"]["pull_on"] == "head_segment"

    @property
    def adhesion_reaction_shared(self) -> bool:
        return self.raw["guiding"]["reaction_on"] == "tail_segment"

    @property
    def suppression_head_only(self) -> bool:
        return self.raw["reversals"]["suppression_contacts"] == "head"

    @property
    def suppression_until_contact_end(self) -> bool:
        return self.raw["reversals"]["suppressed_wait"] == "contact_end"

    @property
    def slime(self) -> bool:
        return self.raw["slime"]["enabled"]

    @property
    def slime_grid(self) -> float:
        """Slime grid element side, µm."""
        return self.raw["slime"]["grid_um"]

    @property
    def slime_f_max(self) -> float:
        """Slime guiding force F_max^s, pN."""
        return self.raw["slime"]["f_max_pN"]

    @property
    def reversal_period_s(self) -> float:      # min -> s
        return self.raw["reversals"]["period_min"] * 60.0

    @property
    def reversal_sd_fraction(self) -> float:
        return self.raw["reversals"]["period_sd_fraction"]

    @property
    def reversal_min_fraction(self) -> float:
        return self.raw["reversals"]["min_period_fraction"]

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
    def mass(self) -> float:
        """Particle mass in pN s^2/µm (1 pg = 1e-15 kg; pN = 1e-12 N; µm/s^2 = 1e-6 m/s^2: x 1e-9); 0: overdamped."""
        return self.raw["run"]["mass_pg"] * 1e-9

    @property
    def skin(self) -> float:
        """Neighbour-list skin, µm."""
        return self.raw["run"]["skin_um"]

    @property
    def max_neighbours(self) -> int:
        """Neighbour-list capacity per segment; 0: from the densest packing."""
        return self.raw["run"]["max_neighbours"]

    @property
    def speed_window_s(self) -> float:
        """Window over which displayed speeds are averaged, s."""
        return self.raw["run"]["speed_window_s"]

    @property
    def dt(self) -> float:
        """Time step in s; 0 in the file means the integrator's default (see stability.py)."""
        ms = self.raw["run"]["dt_ms"]
        return (ms if ms > 0 else default_dt_ms(self)) * 1e-3

    @property
    def step_control(self) -> str:
        """"fixed" or "error" (taichimyxo/physics/integrators/step_control.py)."""
        return self.raw["run"]["step_control"]

    @property
    def step_tolerance_um(self) -> float:
        return self.raw["run"]["step_tolerance_um"]

    @property
    def step_max_multiple(self) -> int:
        return self.raw["run"]["step_max_multiple"]

    @property
    def longest_step(self) -> float:
        """The longest step a run takes, s: run.dt_ms, or step_max_multiple of it under step control."""
        return self.dt * (self.step_max_multiple if self.step_control == "error" else 1)

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
