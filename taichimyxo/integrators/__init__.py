"""Time integrators, one module each, chosen by the scene's run.integrator (docs/model.md "Equation of motion"):
  explicit  the paper's overdamped Euler step, or with run.mass_pg > 0 the semi-implicit (mass-spring) step;
  imex      linearly implicit Euler on springs, bending and contacts (stiff scenes, large steps);
  imex-explicit  the same with contacts explicit (springs and bending implicit; docs/accuracy.md).
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


IMEX = ("imex", "imex-explicit")


def imex_options(scene, options: dict) -> dict:
    """The options of the scene's imex step: run.integrator = "imex-explicit" is imex with contacts = "explicit"."""
    if scene.integrator != "imex-explicit":
        return options
    if options.get("contacts", "explicit") != "explicit":
        raise ValueError(f"contacts={options['contacts']!r} contradicts run.integrator = 'imex-explicit'")
    return {**options, "contacts": "explicit"}


def make_integrator(scene, state, model, neighbours, builder, **options):
    if scene.integrator in IMEX:
        from .imex import Imex
        return Imex(scene, state, model, neighbours, builder, **imex_options(scene, options))
    if options:
        raise ValueError(f"options {sorted(options)} apply to run.integrator = 'imex' only")
    from .explicit import Explicit
    return Explicit(scene, state, model, neighbours, builder)


def records_contacts(scene, **options) -> bool:
    """The integrator needs every contact recorded for its Jacobian (imex with implicit contacts)."""
    return scene.integrator in IMEX and imex_options(scene, options).get("contacts", "coupled") != "explicit"
