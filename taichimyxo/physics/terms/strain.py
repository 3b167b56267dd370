"""Strain energy per segment (docs/model.md "What is measured"): the contact energy w k_c (W - d)^2 / 2 of each
sample contact (terms/contacts.py), half to the segment pressed and half to the sample's own segment (a particle's
half shared by the two segments meeting there). The segment energies sum to the contact energy whose gradient is
the contact force; docs/model.md says how this differs from the paper's all-pairs sum. Allocated and computed only
in scenes that log strain (output.strain)."""

import numpy as np
import taichi as ti

from .base import Term


@ti.data_oriented
class Strain(Term):
    name = "strain"

    def __init__(self, contacts, builder):
        self.contacts = contacts
        st = contacts.state
        self.N, self.n_cells, self.n_s, self.loops = st.N, st.n_cells, st.n_s, st.loops
        self.strain_seg = st.scalar(builder, st.n_s, ti.f64)

    @ti.kernel
    def _compute(self):
        ct = self.contacts
        nl = self.contacts.nl
        N = ti.static(self.N)
        ti.loop_config(**self.loops.items)
        for s in range(self.n_s):
            e = ti.cast(0.0, ti.f64)
            ks = s % (N - 1)
            for q in range(nl.nbr_n[s]):
                t = nl.nbr[s, q]
                if not ct.within_reach(s, t):
                    continue
                t_last = t % (N - 1) == N - 2
                for k in range(6):                               # as the force: own samples, then t's
                    j = k % 3
                    if k < 3:
                        share = 0.5                              # the midpoint's half is all this segment's
                        if j != 1:
                            share = 0.25                         # a particle's half, shared with the neighbour
                            if (j == 0 and ks == 0) or (j == 2 and ks == N - 2):
                                share = 0.5                      # a pole has one segment
                        e += share * ct.sample_energy(s, j, t)
                    elif j < 2 or t_last:
                        e += 0.5 * ct.sample_energy(t, j, s)
            self.strain_seg[s] = e

    def segment_strain(self) -> np.ndarray:
        """(n_cells, N-1) strain energy in J (pN·µm = 1e-18 J)."""
        self._compute()
        return self.strain_seg.to_numpy().reshape(self.n_cells, self.N - 1) * 1e-18
