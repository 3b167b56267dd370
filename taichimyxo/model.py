"""The force field: the model's terms (taichimyxo/terms/, one file per docs/model.md term) composed at compile time.

A scene's effects decide which units exist (`Model.units`); the kernels iterate over them with `ti.static`, so an
effect a scene does not use is neither compiled nor allocated. The integrators (taichimyxo/integrators/) call, in
one fused kernel per step:
    pairs()             parallel loop over segments: each contact pair evaluated once by its lower segment; head
                        and tail segments gather guiding from their own short list
    cell_forces(c)      per cell, in its own frame: internal terms (springs, bending), engine, then the per-cell
                        terms (contacts gathered, guiding, slime)
    after_move(c, m, dt) per cell after its particles moved: neighbour-list flag, slime claim or reversal clock
    deposit(c, dt)      per cell, a last loop when slime is on: the slime write, then the reversal clock

Adding a force law: write its unit in taichimyxo/terms/ (parameters from the scene, fields, `add_cell_forces` or
`pair_pass`, numpy energy, stiffness if stiff) and list it in `Model.__init__`.
"""

import numpy as np
import taichi as ti

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
    def __init__(self, scene, state, neighbours, fb, record_contacts: bool = False):
        self.state, self.nl = state, neighbours
        self.N = scene.N
        self.springs = Springs(scene)
        self.bending = Bending(scene)
        self.engine = Engine(scene, state)
        self.contacts = Contacts(scene, state, neighbours, fb, record=record_contacts)
        head_tail = scene.guiding != "none" or scene.suppression
        self.guiding = HeadToTail(scene, state, neighbours, fb) if head_tail else None
        self.slime = Slime(scene, state, fb) if scene.slime else None
        self.reversals = Reversals(scene, state, fb, self.guiding) if scene.reversals else None
        self.strain = Strain(self.contacts, fb) if scene.strain else None
        self.has_guiding = self.guiding is not None       # compile-time flags (`is` cannot appear in a kernel)
        self.has_slime = self.slime is not None
        self.has_reversals = self.reversals is not None
        # compile-time lists: what the kernels iterate over
        self.internal = [self.springs, self.bending]
        self.pair_terms = [u for u in (self.contacts, self.guiding) if u is not None]
        pulls = self.guiding is not None and scene.guiding != "none"
        self.cell_terms = [u for u in (self.contacts, self.guiding if pulls else None, self.slime) if u is not None]
        self.units = [u for u in (self.springs, self.bending, self.engine, self.contacts, self.guiding, self.slime,
                                  self.reversals, self.strain) if u is not None]

    # ------------------------------------------------------------------ in kernels
    @ti.func
    def pairs(self):
        st = self.state
        ti.loop_config(**st.loops.items)
        for s in range(st.n_s):
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
        """After cell c's update: neighbour-list flag, then the slime claim (the reversal follows the slime write,
        in deposit) or the reversal clock."""
        self.nl.flag_moved(moved)
        if ti.static(self.has_slime):
            self.slime.claim(c)
        elif ti.static(self.has_reversals):
            self.reversals.advance(c, dt)

    @ti.func
    def deposit(self, c, dt):
        self.slime.write(c)
        if ti.static(self.has_reversals):
            self.reversals.advance(c, dt)

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
            fb = ti.FieldsBuilder()
            fields = [ti.Vector.field(2, dtype=ti.f64) for _ in range(3)]
            fb.dense(ti.i, st.n_p).place(*fields)
            self._out = (*fields, fb.finalize())
        f_int, f_tot, tan, _ = self._out
        self._evaluate(f_int, f_tot, tan)
        sh = (st.n_cells, st.N, 2)
        return {"internal": f_int.to_numpy().reshape(sh), "total": f_tot.to_numpy().reshape(sh),
                "contact": self.contacts.per_particle(), "tangent": tan.to_numpy().reshape(sh)}

    def close(self) -> None:
        self.contacts.close()
        if getattr(self, "_out", None) is not None:
            self._out[3].destroy()
            self._out = None

    # ------------------------------------------------------------------ state of the units
    CHECKPOINTED = {"reversals": ("rev_clock", "rev_period", "rev_count", "rev_suppressed"), "slime": ("slime",)}

    def checkpoint_fields(self) -> dict:
        """Name -> field of every unit's state that a checkpoint must carry."""
        out = {}
        for unit, names in self.CHECKPOINTED.items():
            u = getattr(self, unit)
            if u is not None:
                out.update({n: getattr(u, n) for n in names})
        return out


def fields_of(obj) -> dict:
    """Name -> field of the Taichi fields an object holds as attributes."""
    return {k: f for k, f in vars(obj).items() if isinstance(f, (ti.Field, ti.MatrixField))}


def field_bytes(f) -> int:
    n = int(np.prod(f.shape))
    return n * (f.n * f.m if isinstance(f, ti.MatrixField) else 1) * (8 if f.dtype in (ti.f64, ti.i64) else 4)
