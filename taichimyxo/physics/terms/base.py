"""The term protocol: the hooks a unit of taichimyxo/physics/terms/ may implement.

A unit subclasses `Term` and overrides the hooks it needs; Model (taichimyxo/physics/model.py) lists the units a scene
turns on and builds, at compile time, one list per hook of the units that implement it, in the order the units are
listed. The kernels iterate those lists with `ti.static`, so a hook nobody implements costs nothing. In kernels
(@ti.func):

    add_forces(U, Ln, Fi) -> Fi          internal forces of one cell in its own frame (unit segment vectors U,
                                         lengths Ln), added to Fi (N x 2) before the engine
    pair_pass(s)                         once per segment s in the parallel pair loop (contacts, head-to-tail)
    add_cell_forces(c, T, F) -> F        per cell after the engine: F (N x 2) += this term's forces, T the forward
                                         tangents
    add_stiffness(band, c, xrel, dt)     dt K of this term into cell c's banded matrix (the linearly implicit step,
                                         integrators/imex.py); xrel holds the cell's chain offsets
    add_coupling(c, y, out, dt)          out -= the part of dt K y that couples cell c to other cells (a stiffness
                                         between cells; imex's "explicit" contact mode leaves such terms explicit)
    after_move(c, dt)                    per cell once its particles have moved
    last_loop(c, dt)                     per cell in a last loop over cells, run only when some unit implements it
                                         (a write that must follow every cell's after_move: the slime write)

On the host (Python, default: nothing):

    start()                              after the initial state is loaded (reversal periods and phases)
    checkpoint_fields() -> {name: field} the unit's state a checkpoint carries (ADDED_LATER: names older
                                         checkpoints may lack, left at 0 when loading them)
    hold_clock(held)                     a rollback splits a scene step: hold step-counting clocks on its parts
    close()                              free fields made on first use

`after_last_loop = True` moves a unit's after_move into the last loop (after the last_loop hooks) when there is
one: a reversal follows the slime write of the same step (docs/model.md "Force terms").
"""

KERNEL_HOOKS = ("add_forces", "pair_pass", "add_cell_forces", "add_stiffness", "add_coupling", "after_move",
                "last_loop")


class Term:
    name = "term"
    after_last_loop = False
    ADDED_LATER: tuple = ()

    def hooks(self) -> set:
        """The kernel hooks this unit implements: those its class overrides (a unit may drop one it does not use
        in this scene)."""
        return {h for h in KERNEL_HOOKS if getattr(type(self), h) is not getattr(Term, h)}

    # ------------------------------------------------------------------ kernel hooks (documentation; never called)
    def add_forces(self, U, Ln, Fi):
        raise NotImplementedError

    def pair_pass(self, s):
        raise NotImplementedError

    def add_cell_forces(self, c, T, F):
        raise NotImplementedError

    def add_stiffness(self, band, c, xrel, dt):
        raise NotImplementedError

    def add_coupling(self, c, y, out, dt):
        raise NotImplementedError

    def after_move(self, c, dt):
        raise NotImplementedError

    def last_loop(self, c, dt):
        raise NotImplementedError

    # ------------------------------------------------------------------ host hooks
    def start(self) -> None:
        pass

    def checkpoint_fields(self) -> dict:
        return {}

    def hold_clock(self, held: bool) -> None:
        pass

    def close(self) -> None:
        pass
