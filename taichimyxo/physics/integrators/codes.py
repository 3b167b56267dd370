"""What a step kernel returns: one integer (one value read back per step), shared by the integrators and the step
controller (a module of its own, so that neither imports the package that imports them)."""

import taichi as ti

# A step kernel returns one integer (one value read back per step): bit 0 says the neighbour list must be rebuilt,
# the bits above carry the step controller's quantised error ratio (step_control.py; 0 without it).
REBUILD_BIT = 1


def needs_rebuild(code: int) -> int:
    """1 when the step that returned `code` left the neighbour list to rebuild."""
    return code & REBUILD_BIT


def error_ratio_code(code: int) -> int:
    """The step controller's quantised e / tol carried by `code`."""
    return code >> 1


@ti.func
def step_code(rebuild, ratio_code):
    """What a step kernel returns."""
    return rebuild + 2 * ratio_code
