"""The force field: the model's terms (taichimyxo/physics/terms/, one file per docs/model.md term) composed at compile
time.

A scene's effects decide which units exist (`Model.units`); each unit implements hooks of the term protocol
(taichimyxo/physics/terms/base.py), and the model keeps, at compile time, one list per hook of the units that implement
it. The kernels iterate those lists with `ti.static`, so an effect a scene does not use is neither compiled nor
allocated. The integrators (taichimyxo/physics/integrators/) call, in one fused kernel per step:
    pairs()             parallel loop over segments: every unit's pair_pass (contacts, head-to-tail)
    cell_forces(c)      per cell, in its own frame: internal forces (add_forces), the engine, then the per-cell
                        forces (add_cell_forces)
    after_move(c, m, dt) per cell after its particles moved: the neighbour-list flag, then every unit's after_move
    last_loop(c, dt)    per cell, a last loop when a unit needs one (has_last_loop): every unit's last_loop, then the
                        after_move of units that follow it
and the linearly implicit step iterates `stiff_terms` (add_stiffness) and `coupling_terms` (add_coupling).

Adding a force law: write its unit in taichimyxo/physics/terms/ (a Term: parameters from the scene, fields, its hooks,
numpy energy, stiffness if stiff) and add one line to `Model.__init__`.
"""

import numpy as np
import taichi as ti

from .terms.base import Term
from .terms.bending import Bending
from .terms.contacts import Contacts
from .terms.engine import Engine
from .terms.guiding import HeadToTail
from .terms.reversals import Reversals
from .terms.slime import Slime
from .terms.springs import Springs
from .terms.strain import Strain


@ti.data_oriented
class Model:
    def __init__(self, scene, state, neighbours, builder, record_contacts: bool = False):
        self.state, self.nl = state, neighbours
        self.N = scene.N
        # one line per unit, in the order the kernels apply them (the order of every sum: runs depend on it)
        self.springs = Springs(scene)
        self.bending = Bending(scene)
        self.engine = Engine(scene, state)          # not a hook: its tangents are every cell's frame
        self.contacts = Contacts(scene, state, neighbours, builder, record=record_contacts)
        head_tail = scene.guiding != "none" or scene.suppression
        self.head_to_tail = HeadToTail(scene, state, neighbours, builder) if head_tail else None
        self.slime = Slime(scene, state, builder) if scene.slime else None
        self.reversals = Reversals(scene, state, builder, self.head_to_tail) if scene.reversals else None
        self.strain = Strain(self.contacts, builder) if scene.strain else None
        self.units: list[Term] = [u for u in (self.springs, self.bending, self.engine, self.contacts, self.head_to_tail,
                                              self.slime, self.reversals, self.strain) if u is not None]
        # compile-time lists: what the kernels iterate over
        self.internal = self.implementing("add_forces")
        self.pair_terms = self.implementing("pair_pass")
        self.cell_terms = self.implementing("add_cell_forces")
        self.stiff_terms = self.implementing("add_stiffness")
        self.coupling_terms = self.implementing("add_coupling")
        self.last_loop_terms = self.implementing("last_loop")
        self.has_last_loop = bool(self.last_loop_terms)
        moving = self.implementing("after_move")
        self.late_terms = [u for u in moving if u.after_last_loop and self.has_last_loop]
        self.move_terms = [u for u in moving if u not in self.late_terms]

    def implementing(self, hook: str) -> list:
        """The units that implement `hook` (terms/base.py), in the order of `units`."""
        return [u for u in self.units if hook in u.hooks()]

    # ------------------------------------------------------------------ in kernels
    @ti.func
    def pairs(self):
        st = self.state
        ti.loop_config(**st.loops.items)
        for i in range(st.n_s):
            s = st.segment_of(i)                    # the threads' shares spread over the cells (launch.py)
            for u in ti.static(self.pair_terms):
                u.pair_pass(s)

    @ti.func
    def geometry(self, c):
        """Cell c in its own frame (mixed precision: f64 origin x0, force-precision offsets): X (N x 2) offsets from
        particle 0, U (N-1 x 2) unit segment vectors k -> k+1, Ln their lengths."""
        st = self.state
        N = ti.static(self.N)
        base = c * N
        x0 = st.x[base]
        X = ti.Matrix.zero(st.fdt, N, 2)
        for k in ti.static(range(1, N)):
            d = ti.cast(st.mi(st.x[base + k] - st.x[base + k - 1]), st.fdt)
            X[k, 0] = X[k - 1, 0] + d[0]
            X[k, 1] = X[k - 1, 1] + d[1]
        U = ti.Matrix.zero(st.fdt, N - 1, 2)
        Ln = ti.Vector.zero(st.fdt, N - 1)
        for k in ti.static(range(N - 1)):
            l = ti.Vector([X[k + 1, 0] - X[k, 0], X[k + 1, 1] - X[k, 1]])
            ln = l.norm()
            Ln[k] = ln
            u = l / ln
            U[k, 0] = u[0]
            U[k, 1] = u[1]
        return x0, X, U, Ln

    @ti.func
    def cell_forces(self, c):
        """Forces on the N particles of cell c: (x0, X offsets, F total, T forward tangents, Fi internal)."""
        x0, X, U, Ln = self.geometry(c)
        Fi = ti.Matrix.zero(self.state.fdt, self.N, 2)
        for u in ti.static(self.internal):
            Fi = u.add_forces(U, Ln, Fi)
        T = self.engine.tangents(c, U)
        F = self.engine.forces(Fi, T)
        for u in ti.static(self.cell_terms):
            F = u.add_cell_forces(c, T, F)
        return x0, X, F, T, Fi

    @ti.func
    def after_move(self, c, moved, dt):
        """After cell c's update: the neighbour-list flag, then each unit's after_move (a slime claim, a reversal
        clock unless it follows the last loop)."""
        self.nl.flag_moved(moved)
        for u in ti.static(self.move_terms):
            u.after_move(c, dt)

    @ti.func
    def last_loop(self, c, dt):
        """Cell c in the last loop over cells (has_last_loop): the slime write, then a reversal clock."""
        for u in ti.static(self.last_loop_terms):
            u.last_loop(c, dt)
        for u in ti.static(self.late_terms):
            u.after_move(c, dt)

    # ------------------------------------------------------------------ measurements
    @ti.kernel
    def _evaluate(self, f_int: ti.template(), f_tot: ti.template(), tan: ti.template()):
        st = self.state
        self.pairs()
        ti.loop_config(**st.loops.items)
        for c in range(st.n_cells):
            x0, X, F, T, Fi = self.cell_forces(c)
            for k in ti.static(range(self.N)):
                p = c * self.N + k
                f_int[p] = ti.cast(ti.Vector([Fi[k, 0], Fi[k, 1]]), ti.f64)
                f_tot[p] = ti.cast(ti.Vector([F[k, 0], F[k, 1]]), ti.f64)
                tan[p] = ti.cast(ti.Vector([T[k, 0], T[k, 1]]), ti.f64)

    def forces(self) -> dict:
        """Forces at the current state without stepping: 'internal' (springs + bending), 'contact' (per particle),
        'total' (everything the step uses), 'tangent'. Arrays (n_cells, N, 2), pN. Fields for the output are
        made on first use and kept (a measurement, not part of a run's memory)."""
        st = self.state
        if getattr(self, "_out", None) is None:
            builder = ti.FieldsBuilder()
            fields = [ti.Vector.field(2, dtype=ti.f64) for _ in range(3)]
            builder.dense(ti.i, st.n_p).place(*fields)
            self._out = (*fields, builder.finalize())
        f_int, f_tot, tan, _ = self._out
        self._evaluate(f_int, f_tot, tan)
        sh = (st.n_cells, st.N, 2)
        return {"internal": f_int.to_numpy().reshape(sh), "total": f_tot.to_numpy().reshape(sh),
                "contact": self.contacts.per_particle(), "tangent": tan.to_numpy().reshape(sh)}

    def close(self) -> None:
        for u in self.units:
            u.close()
        if getattr(self, "_out", None) is not None:
            self._out[3].destroy()
            self._out = None

    # ------------------------------------------------------------------ state of the units
    def start(self) -> None:
        """The initial state is loaded: each unit starts (reversal periods and phases)."""
        for u in self.units:
            u.start()

    def hold_clocks(self, held: bool) -> None:
        """Hold every step-counting clock during the parts of one split scene step (a rollback's redo)."""
        for u in self.units:
            u.hold_clock(held)

    def checkpoint_fields(self) -> dict:
        """Name -> field of every unit's state that a checkpoint must carry."""
        out = {}
        for u in self.units:
            out.update(u.checkpoint_fields())
        return out

    def added_later(self) -> set:
        """Checkpoint fields older checkpoints may lack (left at 0 when loading them)."""
        return {n for u in self.units for n in u.ADDED_LATER}


def fields_of(obj) -> dict:
    """Name -> field of the Taichi fields an object holds as attributes."""
    return {k: f for k, f in vars(obj).items() if isinstance(f, (ti.Field, ti.MatrixField))}


def field_bytes(f) -> int:
    n = int(np.prod(f.shape))
    return n * (f.n * f.m if isinstance(f, ti.MatrixField) else 1) * (8 if f.dtype in (ti.f64, ti.i64) else 4)
