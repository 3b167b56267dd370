"""A figure as one composite image: its panels (the first or last frame of its runs, drawn by the movies' renderer
without decorations), each with its letter and label, one colour bar per colouring shown (speed; strain energy where
a panel shows it, as the paper's Fig 2 and Fig 4), the panels' time, one scale bar and the caption, which says the
scale, the runs and what the figure cannot show at that scale. PNG, and PDF for print; beside it the claims table
measured on the figure's runs (the stiffness figures: the stiffness series, taichimyxo.figures.stiffness)."""
from __future__ import annotations

import json
import os
import textwrap
from pathlib import Path

import numpy as np

PANEL_PX = 900               # the largest side of a panel's rendering, px
PANEL_IN = 3.2               # a panel's width in the composite, inches
TITLE_CHARS = 44             # a panel title's line at 9 pt fits the panel's width
PAPER_HOURS = {"Fig3": 3.0}  # the paper's final configurations: 3 h for Fig 3, 6 h for the others


def figure_files(runs, out: Path) -> dict:
    """Where the composite goes: OUT/NAME.png, .pdf and .json (its panels, runs and caption) at paper scale,
    OUT/NAME.SCALE.png / .pdf / .json otherwise."""
    stem = runs.figure.name if runs.scale_name == "paper" else f"{runs.figure.name}.{runs.scale_name}"
    return {k: Path(out) / f"{stem}.{k}" for k in ("png", "pdf", "json")}


def panel_image(frame, color: str):
    """The box region of the frame rendered in `color` (RGB uint8)."""
    from ..render import Renderer
    r = Renderer((PANEL_PX, PANEL_PX), color, frame.box, decorations=False)
    return r.render(frame)[r.viewport.slices]


def _colorbar(fig, rect, color: str):
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import ListedColormap, LogNorm, Normalize

    from ..render import make_scale
    sc = make_scale(color)
    norm = LogNorm(sc.vmin, sc.vmax) if sc.log else Normalize(sc.vmin, sc.vmax)
    sm = ScalarMappable(norm=norm, cmap=ListedColormap(np.asarray(sc.lut) / 255.0))
    cax = fig.add_axes(rect)
    cb = fig.colorbar(sm, cax=cax, orientation="horizontal")
    cb.set_ticks(list(sc.ticks))
    cb.set_ticklabels(list(sc.tick_labels))
    cb.minorticks_off()
    cb.set_label(sc.label, fontsize=9)
    cb.ax.tick_params(labelsize=8)


def panel_title(label: str, when: str) -> str:
    """A panel's label and time ('t = 6 h 00 min') wrapped to the panel's width, the time never split."""
    lines = textwrap.wrap(label, TITLE_CHARS)
    if when:
        if lines and len(lines[-1]) + 3 + len(when) <= TITLE_CHARS:
            lines[-1] += f",  {when}"
        else:
            lines.append(when)
    return "\n".join(lines)


def _scalebar(ax, box) -> None:
    from ..render.layout import nice_scalebar_length
    Lx, Ly = box
    bar = nice_scalebar_length(Lx, 0.25)
    x1, y = 0.96 * Lx, 0.05 * Ly
    ax.plot([x1 - bar, x1], [y, y], color="black", lw=3, solid_capstyle="butt", zorder=5)
    ax.text(x1 - bar / 2, y + 0.02 * Ly, f"{bar:g} µm", ha="center", va="bottom", fontsize=8, zorder=5,
            bbox=dict(facecolor="white", edgecolor="none", alpha=0.7, pad=1))


def caption_text(runs, frames: dict, notes: list[str]) -> str:
    """The caption: the paper's, the scale and runs, what the scale cannot show, panels shorter than the paper's
    run (frames: letter -> time s of its frame)."""
    from ..render import format_time
    fig = runs.figure
    p0 = runs.points[0].scene
    w, h = p0.box
    cells = sorted({p.scene.n_cells for p in runs.points})
    scale = (f"Scale: {runs.scale_name} ({w:g} x {h:g} µm, {'/'.join(map(str, cells))} cells; the paper's box "
             f"is the scenes' own). Panels: seed {runs.sweep.seeds[0]} of the runs of {fig.sweep} "
             f"({len(runs.sweep.seeds)} seed{'s' if len(runs.sweep.seeds) > 1 else ''}); scenes {fig.scenes}.")
    parts = [fig.caption, scale]
    if runs.scale_name in fig.scale_notes:
        parts.append(fig.scale_notes[runs.scale_name])
    last = {p.letter for p in fig.panels if p.frame == "last"}
    short = [f"{k} ends at {format_time(t)[4:]}" for k, t in frames.items() if k in last and t is not None
             and t + 1.0 < PAPER_HOURS.get(fig.name, 6.0) * 3600]
    if short:
        parts.append("Shorter than the paper's run (not its final configuration): " + "; ".join(short) + ".")
    return " ".join(parts + notes)


def _source(runs, pt, out: Path) -> str | None:
    """Where a panel's frame comes from, never a machine's path: the run's trajectory relative to the figure's folder,
    or its record relative to the records' folder ("record: NAME.SCALE/<run>.npz")."""
    if pt is None:
        return None
    rec = runs.record_file(pt) if runs.records is not None else None
    if runs.trajectory(pt).is_file() or rec is None:
        return os.path.relpath(runs.trajectory(pt), out)
    return "record: " + os.path.relpath(rec, Path(runs.records))


def compose_figure(runs, out: Path) -> list[Path]:
    """Draw the figure from its runs' trajectories into OUT (figure_files); with the stiffness series for S2 Fig
    and S3 Fig. Returns the files written."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..render import format_time
    fig_spec = runs.figure
    panels = fig_spec.panels
    n = len(panels)
    ncols = 2 if n == 4 else min(n, 3)
    nrows = -(-n // ncols)
    box = runs.points[0].scene.box
    aspect = box[1] / box[0]
    colors = sorted({p.color for p in panels}, key=["speed", "strain"].index)
    width = PANEL_IN * ncols
    cap = caption_text(runs, {}, [])
    cap_lines = len(textwrap.wrap(cap, int(width * 16))) + 2
    height = nrows * (PANEL_IN * aspect + 0.45) + 0.9 + 0.16 * cap_lines + 0.5
    fig = plt.figure(figsize=(width, height))
    top = 1.0 - 0.5 / height
    ph = 0.92 / ncols * width * aspect / height
    frames, notes, drawn = {}, [], []
    for i, panel in enumerate(panels):
        r, c = divmod(i, ncols)
        y0 = top - (r + 1) * (ph + 0.45 / height) + 0.05 / height
        ax = fig.add_axes([0.03 + c * 0.96 / ncols + 0.02 / ncols, y0, 0.92 / ncols, ph])
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_xlim(0, box[0])
        ax.set_ylim(0, box[1])
        ax.text(-0.02, 1.03, panel.letter, transform=ax.transAxes, fontsize=14, fontweight="bold", va="bottom",
                ha="right")
        pt = runs.first_seed_point(panel.match)
        frame = runs.frame(pt, panel.frame) if pt is not None else None
        frames[panel.letter] = frame.time_s if frame is not None else None
        if frame is not None and panel.color == "strain" and frame.segment_strain is None:
            frame = frame.with_strain(pt.scene.width, pt.scene.k_c)
            notes.append(f"{panel.letter}: strain energy computed from the frame's positions (its run did not log "
                         f"it).")
        img = panel_image(frame, panel.color) if frame is not None else None
        if img is None:
            why = "run missing"
            ax.text(0.5, 0.5, why, transform=ax.transAxes, ha="center", va="center", fontsize=10)
            notes.append(f"{panel.letter}: {why}.")
        else:
            ax.imshow(img, extent=(0, box[0], 0, box[1]), interpolation="antialiased")
        drawn.append(dict(letter=panel.letter, label=panel.label, color=panel.color, frame=panel.frame,
                          run=_source(runs, pt, Path(out)),
                          time_s=frame.time_s if frame is not None else None, drawn=img is not None))
        when = format_time(frame.time_s) if frame is not None else ""
        ax.set_title(panel_title(panel.label, when), fontsize=9, loc="left", pad=3)
        if i == n - 1:
            _scalebar(ax, box)
    bar_y = top - nrows * (ph + 0.45 / height) - 0.35 / height
    for k, color in enumerate(colors):
        _colorbar(fig, [0.08 + k * 0.5, bar_y, 0.36, 0.12 / height], color)
    fig.suptitle(fig_spec.title, x=0.02, y=1.0 - 0.08 / height, ha="left", va="top", fontsize=11)
    text = caption_text(runs, frames, notes)
    fig.text(0.02, bar_y - 0.55 / height, "\n".join(textwrap.wrap(text, int(width * 16))), ha="left", va="top",
             fontsize=7.5)
    files = figure_files(runs, out)
    Path(out).mkdir(parents=True, exist_ok=True)
    for k in ("png", "pdf"):
        fig.savefig(files[k], dpi=150)
    plt.close(fig)
    files["json"].write_text(json.dumps(dict(figure=fig_spec.name, title=fig_spec.title, scale=runs.scale_name,
                                             box_um=list(box), seeds=runs.sweep.seeds, panels=drawn, caption=text,
                                             sweep=os.path.relpath(runs.root / "sweep.toml", out)), indent=1))
    written = list(files.values())
    if fig_spec.stiffness:
        from .stiffness import write_stiffness
        written += write_stiffness(runs, out)
    else:
        written += write_claims(runs, out)
    return written


def write_claims(runs, out: Path) -> list[Path]:
    """The claims table (taichimyxo.analysis.claims) over the figure's runs, in OUT/NAME[.SCALE].claims/: what the
    paper says of the runs the figure shows, measured on their trajectories, or on the analysis its record kept
    where a run's folder is gone. Without either for every run, nothing is written."""
    from ..analysis.claims import claims

    def source(pt):
        if runs.trajectory(pt).is_file():
            return runs.trajectory(pt)
        rec = runs.record(pt)
        return rec.path if rec is not None and rec.analysis else None
    paths = [source(pt) for pt in runs.points]
    if None in paths:
        return []
    folder = Path(out) / f"{figure_files(runs, out)['png'].stem}.claims"
    return [Path(f) for f in claims([str(p) for p in paths], out_dir=str(folder))["files"]]
