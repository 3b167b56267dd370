"""The model's terms (docs/model.md "Force terms"), one unit per file: springs (1), bending (2), engine (3),
contacts (4), guiding (5, with the head-to-tail interaction that suppresses reversals), slime (6), reversals (7),
and strain (the measured contact energy per segment). Each unit holds its parameters (from the Scene, in internal
units), its fields (allocated only when the scene uses it), its @ti.func contribution, its numpy energy for the
finite-difference tests and, for the stiff terms, its stiffness block for the linearly implicit step.
taichimyxo/physics/model.py composes the units a scene turns on."""
