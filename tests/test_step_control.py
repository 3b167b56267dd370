"""The step-size controller, run.step_control = "error" (taichimyxo/physics/integrators/step_control.py): the rule, a
free cell at the longest step with its clock exact, a guiding pull's onset that shortens the steps, reversal clocks in
scene steps, and the combinations refused at load. 1 and 2 threads (test_threads.py) and --resume (test_interrupt.py)
are tested with the other effects."""
import math

import numpy as np
import pytest

from simtools import build_small_scene, cell
from taichimyxo.io.scene import SceneError
from taichimyxo.physics.integrators.step_control import RATIO_SCALE, StepControl

CONTROL = {"step_control": "error", "dt_ms": 2.0, "step_max_multiple": 3}


def _rule(max_multiple=3):
    """The controller's host rule without fields (took() touches none)."""
    c = object.__new__(StepControl)
    c.max_multiple, c.multiple, c.steps_taken, c.ticks = max_multiple, 1, 0, 0
    return c


def _code(ratio, rebuild=0):
    return rebuild + 2 * int(round(ratio * RATIO_SCALE))


def test_the_rule_grows_by_one_shrinks_at_once_and_ignores_cut_steps():
    c = _rule()
    assert c.took(_code(0.01, rebuild=1), 1) == 1          # the rebuild flag comes back
    assert c.multiple == 2                                  # 1 / sqrt(0.01) = 10, but growth is one at a time
    c.took(_code(0.0), 2)
    assert c.multiple == 3                                  # and never beyond step_max_multiple
    c.took(_code(0.0), 3)
    assert c.multiple == 3
    c.took(_code(2.0), 3)                                   # e = 2 tol at m = 3: m = 3 / sqrt(2) -> 2
    assert c.multiple == 2
    c.took(_code(50.0), 2)                                  # far over: down to a single step
    assert c.multiple == 1
    c.multiple = 3
    c.took(_code(50.0), 1)                                  # a step cut to fit a chunk does not steer
    assert c.multiple == 3
    assert (c.steps_taken, c.ticks) == (6, 12)
    assert c.next_step(2) == 2 and c.next_step(7) == 3


def test_free_cell_runs_at_the_longest_step_on_the_scene_clock(make_sim):
    """A straight free cell moves at v_b whatever the step: after its first steps the controller takes the longest
    step, the clock counts scene steps exactly, and the distance is v_b t."""
    sc = build_small_scene(1, run=CONTROL)
    pos = cell((10.0, 10.0), 0.0)[None]
    sim = make_sim(sc, positions=pos, engine_direction=np.array([1]))
    n = 1501                                               # not a multiple of 3: the last step is cut to fit
    sim.advance(n)
    st = sim.solver_stats()
    assert st["scene_steps"] == n and sim.step_count == n and sim.time == n * sc.dt
    assert st["steps_taken"] <= n // 3 + 4                  # two single steps, one double, then triples
    assert st["multiple"] == 3
    moved = np.linalg.norm(sim.positions()[0, 0] - pos[0, 0])
    assert moved == pytest.approx(sc.v_b * n * sc.dt, rel=1e-4)


def test_a_guided_head_takes_shorter_steps(make_sim):
    """A head entering a leader's guiding range: the pull jumps from 0 to F_max^g at gap d_g (docs/model.md term
    5), the largest error a step can make, so the controller drops to single steps there and grows back."""
    sc = build_small_scene(2, run=CONTROL, guiding={"kind": "active"})
    leader = cell((7.0, 8.0), 90.0)                        # head at the bottom, moving -y; tail end at y = 10.25
    follower = cell((7.0 + 0.8 + 2.25, 10.25), 0.0)        # head 0.8 µm right of the tail end (gap 0.3 > d_g)
    sim = make_sim(sc, positions=np.stack([leader, follower]), engine_direction=np.array([1, 1]))
    sim.advance(200)                                           # 0.03 µm closer: free
    st = sim.solver_stats()
    assert st["multiple"] == 3 and st["steps_taken"] <= 200 // 3 + 4
    sim.advance(1500)                                          # 0.2 µm more: inside d_g after about 0.8 s
    during = sim.solver_stats()["steps_taken"] - st["steps_taken"]
    assert sim.positions()[1, 0, 1] < 10.25 - 0.05         # pulled off its straight path toward the tail
    assert during > 1500 / 3 + 2                           # single steps at the jump, then growing back
    assert sim.solver_stats()["multiple"] == 3


def test_reversal_clocks_count_scene_steps(make_sim):
    """Periods of exactly 300 scene steps (no spread): under the controller a cell reverses as often as the scene
    clock says, the steps past each period carried over."""
    sc = build_small_scene(1, run=CONTROL, reversals={"enabled": True, "period_min": 0.01,
                                                      "period_sd_fraction": 0.0})
    sim = make_sim(sc, positions=cell((10.0, 10.0), 0.0)[None], engine_direction=np.array([1]))
    rv = sim.model.reversals
    clock0, period = int(rv.rev_clock[0]), int(rv.rev_period[0])
    assert period == 300
    n = 3000
    sim.advance(n)
    assert sim.solver_stats()["mean_multiple"] > 2.5         # the controller did take long steps
    assert int(rv.rev_count[0]) == (clock0 + n) // period
    assert int(rv.rev_clock[0]) <= (clock0 + n) % period    # at most the cut of the last step behind


def test_refused_combinations():
    with pytest.raises(SceneError, match="explicit"):
        build_small_scene(1, run={"step_control": "error", "integrator": "imex"})
    from taichimyxo.physics.stability import check_step, stable_limit_ms
    sc = build_small_scene(1, run={**CONTROL, "step_max_multiple": 64})
    assert sc.longest_step * 1e3 > stable_limit_ms(sc)
    with pytest.raises(SceneError, match="step_max_multiple"):
        check_step(sc)
    check_step(sc, force=True)
    assert math.isclose(build_small_scene(1, run=CONTROL).longest_step, 6e-3)
