"""Time integrators, one module each, chosen by the scene's run.integrator (docs/model.md "Equation of motion"):
  explicit  the paper's overdamped Euler step, or with run.mass_pg > 0 the semi-implicit (mass-spring) step;
  imex      linearly implicit Euler on springs, bending and contacts (stiff scenes, large steps).
An integrator owns its kernels and fields and exposes `step(dt) -> flag` (1 when the neighbour list must be
rebuilt), `reset()` (forget solver history after the state was replaced), `checkpoint_fields()` and `stats()`."""


def make_integrator(scene, state, model, neighbours, fb, **options):
    if scene.integrator == "imex":
        from .imex import Imex
        return Imex(scene, state, model, neighbours, fb, **options)
    if options:
        raise ValueError(f"options {sorted(options)} apply to run.integrator = 'imex' only")
    from .explicit import Explicit
    return Explicit(scene, state, model, neighbours, fb)


def records_contacts(scene, **options) -> bool:
    """The integrator needs every contact recorded for its Jacobian (imex with implicit contacts)."""
    return scene.integrator == "imex" and options.get("contacts", "coupled") != "explicit"
