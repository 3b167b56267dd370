"""Kernels launched directly (taichimyxo/runtime/kernel_call.py) run the same compiled code as Taichi's own call: the
same trajectory bit for bit, the same return values; a kernel outside the direct call's shape keeps Taichi's call."""

import numpy as np
import pytest
import taichi as ti

from simtools import build_small_scene, cell
from taichimyxo.runtime.kernel_call import direct
from taichimyxo.runtime.simulation import Simulation

pytestmark = pytest.mark.keeps_taichi


def _start():
    """Three cells, two of them crossing, so contacts and rebuilds happen within a few hundred steps."""
    return np.stack([cell((5.0, 5.0), 0.0), cell((6.5, 3.5), 90.0), cell((12.0, 12.0), 45.0)]), np.array([1, -1, 1])


@pytest.mark.parametrize("integrator,dt_ms", [("explicit", 2.0), ("imex", 20.0), ("imex-explicit", 5.0)])
def test_direct_calls_give_taichis_trajectory_bit_for_bit(integrator, dt_ms):
    scene = build_small_scene(3, box=(20.0, 20.0), guiding={"kind": "active"},
                              run={"integrator": integrator, "dt_ms": dt_ms})
    sim = Simulation.from_positions(scene, *_start())
    try:
        def run():
            sim.set_state(*_start())
            sim.model.start()
            before = sim.rebuilds
            sim.advance(1500)
            return sim.positions().copy(), sim.rebuilds - before

        direct_x, direct_rebuilds = run()                  # direct launches (advance's path)
        sim.neighbours._launch_build = sim.neighbours._build       # Taichi's own calls from here on
        integ = sim.integrator
        if integrator == "explicit":
            integ._launch_step = integ._step
        else:
            integ._launch_begin, integ._launch_iterate, integ._launch_finish = (
                integ._imex_begin, integ._imex_iterate, integ._imex_finish)
        taichi_x, taichi_rebuilds = run()
        assert direct_rebuilds > 1                         # the lists were rebuilt on the way
        assert taichi_rebuilds == direct_rebuilds
        np.testing.assert_array_equal(taichi_x, direct_x)
    finally:
        sim.close()


def test_a_kernel_outside_the_shape_keeps_taichis_call():
    @ti.data_oriented
    class Owner:
        def __init__(self):
            self.f = ti.field(ti.f32, shape=4)

        @ti.kernel
        def fill(self, g: ti.template(), v: ti.f32):
            for i in g:
                g[i] = v

        @ti.kernel
        def total(self, k: ti.i32) -> ti.f32:
            s = 0.0
            for i in range(k):
                s += self.f[i]
            return s

    o = Owner()
    fill = direct(o.fill)
    assert fill is not None and not callable(getattr(fill, "_prepare", None))    # a field argument: Taichi's call
    fill(o.f, 2.0)
    total = direct(o.total)
    assert callable(getattr(total, "_prepare", None))
    assert total(4) == pytest.approx(8.0)                  # Taichi's call, which compiles
    assert total(3) == pytest.approx(6.0)                  # the direct launch
    assert total(4) == o.total(4)
