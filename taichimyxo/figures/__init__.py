"""The paper's figures as composite images, from the runs of a sweep file per figure (sweeps/figures/).

Parts: specs (which run and frame each panel shows, the captions), plan (a figure's runs at a scale, their cost),
compose (the composite image), stiffness (the S2 Fig / S3 Fig series against k_a and the paper's four statements on
stiffness), command (`python -m taichimyxo figures`). docs/figures.md says which figure comes from which scenes."""
from .specs import FIGURES, SCALES, Figure, Panel, figure

__all__ = ["FIGURES", "SCALES", "Figure", "Panel", "figure"]
