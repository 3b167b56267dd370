"""Time integrators, one module each, chosen by the scene's run.integrator (docs/model.md "Equation of motion"):
  explicit  the paper's overdamped Euler step, or with run.mass_pg > 0 the semi-implicit (mass-spring) step;
  imex      linearly implicit Euler on springs, bending and contacts (stiff scenes, large steps);
  imex-explicit  the same with contacts explicit (springs and bending implicit; docs/accuracy.md).
An integrator owns its kernels and fields and exposes `step(dt) -> code` (step_code below), `reset()` (forget solver
history after the state was replaced), `checkpoint_fields()` and `stats()`."""

from .codes import REBUILD_BIT, error_ratio_code, needs_rebuild, step_code  # noqa: F401

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
