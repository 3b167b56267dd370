"""The paper's figures: which runs (a sweep file in sweeps/figures/) give which panel, and what each caption says.

A panel is the first (the start) or last frame of one run of the figure's sweep, picked by its swept values and the
figure's first seed, coloured by speed or strain energy."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..io.catalogue import sweeps_dir

# the figures' sweep files: sweeps/figures/ of the clone, or inside the package in a wheel
SWEEP_DIR = sweeps_dir() / "figures"

# --scale: the box's sides times this (cells with the area: the density is kept)
SCALES = {"paper": 1.0, "half": 0.5, "quarter": 0.25}
# fewer cells than this in a run and its panel no longer shows the pattern the figure is about
MIN_CELLS = 100

STARTS_NOTE = ("The S2 Fig and S3 Fig captions say the cells start 'randomly, as in Fig 3A', but Fig 3A is the dense "
               "aligned start of the high-density population; read here as the random low-density start of Fig 2A "
               "(scene S1's), which 'randomly' and 'low-density population' both describe.")


@dataclass(frozen=True)
class Panel:
    letter: str
    match: dict                  # the run's swept values (dotted key -> value)
    label: str                   # what the panel shows, in the paper's words
    frame: str = "last"          # "first": the start; "last": the end of the run
    color: str = "speed"         # "speed" or "strain"
    scene: str = ""              # the scene of `list` whose run this panel shows (same physics)


@dataclass(frozen=True)
class Figure:
    name: str                    # as `figures` takes it: Fig2, S3Fig, ...
    title: str
    sweep: str                   # the sweep file in sweeps/figures/
    panels: tuple
    scenes: str                  # which scenes of `list` the panels reproduce
    caption: str
    # --scale name -> what the figure cannot show at that scale (said in its caption)
    scale_notes: dict = field(default_factory=dict)
    stiffness: bool = False      # the stiffness series is measured over its runs

    @property
    def sweep_path(self) -> Path:
        return SWEEP_DIR / self.sweep


def _stiffness_panels(prefix: str) -> tuple:
    names = (("A", 1e-18, "very flexible"), ("B", 1e-17, "flexible"), ("C", 1e-16, "rigid"),
             ("D", 1e-15, "very rigid"))
    return tuple(Panel(letter, {"cell.k_a_N_m": ka}, f"{label}, k_a = {ka:g} N·m", scene=f"{prefix}{letter}")
                 for letter, ka, label in names)


SMALL_BOX = ("At this scale the box holds a fraction of the paper's cells, so aggregates can only be as large as the "
             "cells available: fewer and smaller ones than the paper's.")

FIGURES = {f.name: f for f in (
    Figure("Fig2", "Fig 2. Short-range guiding in a low-density population of flexible cells", "Fig2.toml",
           (Panel("A", {"guiding.kind": "none"}, "initial random configuration", frame="first"),
            Panel("B", {"guiding.kind": "none"}, "non-guided"),
            Panel("C", {"guiding.kind": "passive"}, "passive following"),
            Panel("D", {"guiding.kind": "active"}, "active following"),
            Panel("E", {"guiding.kind": "adhesion"}, "head-to-tail adhesion"),
            Panel("F", {"guiding.kind": "active"}, "strain energy, active following", color="strain")),
           "A: start; B: S1; C: S2; D: S3; E: S4; F: S8 (S3's run coloured by strain)",
           "(A) Initial random configuration. (B-E) Final configuration at 6 h: (B) non-guided cells, (C) passive "
           "following, (D) active following, (E) head-to-tail adhesion. (F) Strain energy due to cell overlap, "
           "active following.",
           {"half": SMALL_BOX, "quarter": SMALL_BOX}),
    Figure("Fig3", "Fig 3. Short-range guiding in a high-density population of flexible cells", "Fig3.toml",
           (Panel("A", {"guiding.kind": "none"}, "initial configuration: aligned, random orientations",
                  frame="first"),
            Panel("B", {"guiding.kind": "none"}, "non-guided"),
            Panel("C", {"guiding.kind": "active"}, "active following")),
           "A: start; B: S11; C: S13",
           "(A) Initial configuration: cells densely packed, aligned (each turned by up to 1 degree, as the model "
           "has no noise), oriented randomly. (B) Non-guided cells at 3 h. "
           "(C) Active following at 3 h. The paper notes its 60 µm domain may have been too small for rigid guided "
           "cells to form aggregates at this density (S12, S14); this figure shows flexible cells only.",
           {"half": "At half scale the box is 30 µm, 6 cell lengths: a circular movement wider than that cannot "
                    "form, so the figure can show streams and small swirls, not the paper's stable circular "
                    "movement over the whole population."}),
    Figure("Fig4", "Fig 4. Long-range guiding (slime trails) in a low-density population", "Fig4.toml",
           (Panel("A", {"cell.k_a_N_m": 1e-16}, "rigid cells"),
            Panel("B", {"cell.k_a_N_m": 1e-16}, "strain energy, rigid cells", color="strain"),
            Panel("C", {"cell.k_a_N_m": 1e-17}, "flexible cells")),
           "A: S16; B: S16 coloured by strain; C: S17",
           "Random start, as in Fig 2A. (A) Rigid cells at 6 h. (B) Strain energy due to cell overlap, rigid cells. "
           "(C) Flexible cells at 6 h.",
           {"half": SMALL_BOX, "quarter": SMALL_BOX}),
    Figure("S2Fig", "S2 Fig. Non-guided cells at low density against bending stiffness", "S2Fig.toml",
           _stiffness_panels("S2Fig"), "A-D: S2FigA-D",
           "Final configuration at 6 h of non-guided cells at the four bending stiffnesses. " + STARTS_NOTE,
           {"half": SMALL_BOX, "quarter": SMALL_BOX}, stiffness=True),
    Figure("S3Fig", "S3 Fig. Active following at low density against bending stiffness", "S3Fig.toml",
           _stiffness_panels("S3Fig"), "A-D: S3FigA-D (A is S6's scene, D S7's)",
           "Final configuration at 6 h of cells with active following at the four bending stiffnesses. "
           + STARTS_NOTE, {"half": SMALL_BOX, "quarter": SMALL_BOX}, stiffness=True),
    Figure("S6Fig", "S6 Fig. A prearranged spiral aggregate of cells with active following", "S6Fig.toml",
           (Panel("A", {"cell.k_a_N_m": 1e-16}, "initial spiral configuration", frame="first"),
            Panel("B", {"cell.k_a_N_m": 1e-16}, "rigid cells"),
            Panel("C", {"cell.k_a_N_m": 1e-17}, "flexible cells")),
           "A: start; B: S9; C: S10",
           "(A) Initial configuration: cells head to tail on a spiral. (B) Rigid cells at 6 h. (C) Flexible cells "
           "at 6 h.",
           {"half": "At half scale the spiral holds a quarter of the scenes' 500 cells in a 50 µm periodic box, "
                    "10 cell lengths: a smaller aggregate than the paper's, and a stream leaving it can close on "
                    "itself across the box's edges instead of rejoining an aggregate."}),
)}

# the scene of `list` each panel's run reproduces (same physics; the figure's sweep sets strain logging and scale)
PANEL_SCENES = {"Fig2": {"B": "S1", "C": "S2", "D": "S3", "E": "S4", "F": "S8"}, "Fig3": {"B": "S11", "C": "S13"},
                "Fig4": {"A": "S16", "B": "S16", "C": "S17"}, "S6Fig": {"B": "S9", "C": "S10"}}


def _scene_of(fig: Figure, panel: Panel) -> str:
    return panel.scene or PANEL_SCENES.get(fig.name, {}).get(panel.letter, "")


def figure(name: str) -> Figure | None:
    """The figure called `name` (Fig2, fig2, "Fig 2", S3Fig, "S3 Fig"), or None."""
    key = name.replace(" ", "").replace("_", "").lower()
    return next((f for f in FIGURES.values() if f.name.lower() == key), None)


def scene_panels() -> dict:
    """Scene name -> ' (figures: Fig2 B, ...)': the composite panels its run gives, for `list`."""
    out: dict = {}
    for f in FIGURES.values():
        for p in f.panels:
            scene = _scene_of(f, p)
            if scene:
                out.setdefault(scene, []).append(f"{f.name} {p.letter}")
    return {k: f" (figures: {', '.join(v)})" for k, v in out.items()}
