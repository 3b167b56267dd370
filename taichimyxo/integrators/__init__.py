"""Time integrators, one module each, chosen by the scene's run.integrator (docs/model.md "Equation of motion"):
  explicit  the paper's overdamped Euler step, or with run.mass_pg > 0 the semi-implicit (mass-spring) step;
  imex      linearly implicit Euler on springs, bending and contacts (stiff scenes, large steps).
An integrator owns its kernels and fields and exposes `step(dt) -> code` (step_code below), `reset()` (forget solver
history after the state was replaced), `checkpoint_fields()` and `stats()`."""

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


def make_integrator(scene, state, model, neighbours, builder, **options):
    if scene.integrator == "imex":
        from .imex import Imex
        return Imex(scene, state, model, neighbours, builder, **options)
    if options:
        raise ValueError(f"options {sorted(options)} apply to run.integrator = 'imex' only")
    from .explicit import Explicit
    return Explicit(scene, state, model, neighbours, builder)


def records_contacts(scene, **options) -> bool:
    """The integrator needs every contact recorded for its Jacobian (imex with implicit contacts)."""
    return scene.integrator == "imex" and options.get("contacts", "coupled") != "explicit"
