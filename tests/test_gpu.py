"""The GPU's kernels: the GPU-shaped kernels equal the CPU-shaped ones on the CPU (every suite run), and
on CUDA the same comparison against the CPU, in f32, mixed and f64, plus the free speed (marker `gpu`: skipped with
one line where CUDA is not available; benchmarks/gpu_check.sh runs them on a lent GPU).

One scene carries every unit (contacts, active guiding, reversals with suppression, slime) at a density with many
contacts; the comparison and its tolerances are tests/backend_compare.py's. The run loop's copies to the host are
counted here too: none per step, only where a writer fires or a chunk of steps ends."""
from __future__ import annotations

import functools
import shutil
import subprocess
import sys

import numpy as np
import pytest
from backend_compare import Backend, compare

from simtools import build_small_scene, cell

CPU = Backend("cpu", "cpu")
GPU_ON_CPU = Backend("cpu", "gpu")
CUDA = Backend("cuda")
STEPS = 200                 # 0.4 s at 2 ms: several list rebuilds, slime laid, some reversals
# the CPU stand-in's cells: 4 particles, which halves the compile time of every kernel (unrolled per particle) and
# changes nothing the comparison looks at; the CUDA tests use the paper's 8
LIGHT = 4


def every_unit_scene(precision="mixed", integrator="explicit", particles=8):
    """70 cells on 24 x 24 µm (area fraction 0.30; 11 x 11 grid bins with 8 particles, 7 x 7 with 4, so the blocked
    scan has several blocks), every unit on; short reversal periods so cells reverse within the run. imex: the same
    cells, contacts implicit (the explicit terms are the same code in both steps)."""
    cells = {"particles": particles}
    if integrator == "imex":
        return build_small_scene(48, box=(24.0, 24.0), cell=cells,
                                 run={"precision": precision, "integrator": "imex", "dt_ms": 5.0})
    return build_small_scene(70, box=(24.0, 24.0), cell=cells, guiding={"kind": "active"}, slime={"enabled": True},
                             reversals={"enabled": True, "suppression": True, "period_min": 0.1},
                             run={"precision": precision})


@functools.lru_cache(maxsize=2)
def start_state(particles=8):
    """The scene's random start, placed once in numpy: both backends start from the same numbers."""
    from taichimyxo.physics.placement import initial_configuration
    return initial_configuration(every_unit_scene(particles=particles))


@functools.lru_cache(maxsize=2)
def jammed_patch(particles=8):
    """48 cells in 12 rows of 4, rows 0.46 µm apart (W = 0.5: every cell presses on its neighbours from the first
    step), tilted by up to 2 deg, random polarity: the implicit step's coupled solve has work to do."""
    rng = np.random.default_rng(3)
    l0 = 4.5 / (particles - 1)
    pos = np.stack([cell((3.0 + 6.0 * c + rng.uniform(-0.5, 0.5), 8.0 + 0.46 * r), rng.uniform(-2, 2), N=particles,
                         l0=l0) for r in range(12) for c in range(4)])
    return pos, rng.choice([-1, 1], len(pos))


def _assert_within(d):
    assert d["lists_equal"], d
    assert not d["beyond"], d


# ------------------------------------------------------------------ every run: the GPU shape, on the CPU
def test_gpu_shaped_kernels_equal_the_cpu_shaped_ones_on_the_cpu():
    """Lists (the blocked scan of the grid, parallel bin filling, sorted rows) equal exactly; forces and a 200-step
    run with every unit within the mixed tolerances. Measured: bit for bit (both shapes gather in list order)."""
    pos, ke = start_state(LIGHT)
    d = compare(every_unit_scene(particles=LIGHT), pos, ke, CPU, GPU_ON_CPU, STEPS, "gpu shape on the cpu, every unit")
    assert d["shapes"] == ("cpu", "gpu")
    _assert_within(d)
    assert d["rebuilds"][0] >= 2                   # the build ran during the run too, on both shapes
    assert d["force_rel"] == 0.0 and d["pos_um"] == 0.0


def test_gpu_shaped_implicit_step_equals_the_cpu_shaped_one_on_the_cpu():
    """The implicit step's gpu shape (one partial per cell, two-level reduction) against the CPU's (one block): 20
    steps of 5 ms of a jammed patch take the same CG iterations and agree within 1e-9 µm in f64 (the sums group
    differently; measured: bit for bit, their rounding is below the positions' resolution)."""
    pos, ke = jammed_patch(LIGHT)
    d = compare(every_unit_scene("f64", "imex", LIGHT), pos, ke, CPU, GPU_ON_CPU, 20, "gpu shape on the cpu, imex",
                forces=False)
    _assert_within(d)
    assert d["pos_um"] < 1e-9
    assert d["cg_iterations"][0] == d["cg_iterations"][1] > 20          # the coupled solve did work


def test_the_run_loop_copies_to_the_host_only_where_a_writer_fires(monkeypatch):
    """No field is copied to the host per step: a 60-step drive with no writer copies nothing; with a trajectory
    every 20 steps, copies happen only at steps 0, 20, 40, 60 (the frames). The only per-step read is the 4-byte
    rebuild flag the step kernel returns."""
    import taichi as ti
    from backend_compare import start_backend

    from taichimyxo.io.writers import Writer
    from taichimyxo.runtime.run_loop import drive
    from taichimyxo.runtime.simulation import Simulation
    from taichimyxo.runtime.triggers import Periodic

    start_backend(CPU, "mixed")
    pos, ke = start_state(LIGHT)
    sim = Simulation.from_positions(every_unit_scene(particles=LIGHT), pos, ke,
                                    loop_shape="cpu")                   # compiled for the comparison above
    at = []

    def counted(orig):
        def to_numpy(self, *a, **k):
            at.append(sim.step_count)
            return orig(self, *a, **k)
        return to_numpy

    for cls in (ti.ScalarField, ti.MatrixField):
        monkeypatch.setattr(cls, "to_numpy", counted(cls.to_numpy))

    class Frames(Writer):
        trigger = Periodic(steps=20)

        def write(self, run):
            assert run.frame is not None              # makes the frame: the copies

    drive(sim, 60, [], catch_signals=False)
    assert at == []
    drive(sim, 60, [Frames()], catch_signals=False)
    assert set(at) <= {60, 80, 100, 120} and at
    sim.close()


# ------------------------------------------------------------------ on CUDA (marker gpu)
@functools.lru_cache(maxsize=1)
def _no_cuda_reason() -> str | None:
    """Why CUDA cannot be used here (None: it can). Cheap where there is no NVIDIA driver; otherwise one probe in a
    subprocess, so this process's CPU Taichi is left alone."""
    import os
    if not (shutil.which("nvidia-smi") or os.path.exists("/dev/nvidiactl") or os.path.exists("/proc/driver/nvidia")):
        return "no CUDA GPU here (no NVIDIA driver)"
    probe = ("import taichi as ti; ti.init(arch=ti.cuda, offline_cache=False, log_level=ti.ERROR); "
             "print('ARCH', ti.lang.impl.current_cfg().arch == ti.cuda)")
    try:
        p = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        return "no CUDA GPU here (Taichi's CUDA probe timed out)"
    return None if "ARCH True" in p.stdout else "no CUDA GPU here (Taichi cannot start its CUDA backend)"


@pytest.fixture
def cuda():
    reason = _no_cuda_reason()
    if reason:
        pytest.skip(reason)


@pytest.mark.gpu
@pytest.mark.parametrize("precision", ["f32", "mixed", "f64"])
def test_cuda_equals_the_cpu_within_tolerance(cuda, precision):
    """Every unit (springs, bending, engine, contacts, active guiding, reversals with suppression, slime): lists
    exactly, forces and a 200-step run within backend_compare.TOLERANCES[precision]."""
    pos, ke = start_state()
    d = compare(every_unit_scene(precision), pos, ke, CPU, CUDA, STEPS, "cuda against the cpu, every unit")
    assert d["shapes"] == ("cpu", "gpu")
    _assert_within(d)


@pytest.mark.gpu
def test_cuda_implicit_step_equals_the_cpu_within_tolerance(cuda):
    pos, ke = jammed_patch()
    d = compare(every_unit_scene("f64", "imex"), pos, ke, CPU, CUDA, 20, "cuda against the cpu, imex", forces=False)
    _assert_within(d)


@pytest.mark.gpu
@pytest.mark.parametrize("precision", ["f32", "mixed", "f64"])
def test_cuda_free_cell_moves_at_v_b(cuda, precision):
    """A free straight cell moves at v_b = 4 µm/min along its axis on CUDA (tests/test_forces.py's check)."""
    from backend_compare import report, start_backend

    from taichimyxo.runtime.simulation import Simulation
    scene = build_small_scene(1, run={"precision": precision, "dt_ms": 1.0})
    start_backend(CUDA, precision)
    pos = cell((7.3, 11.1), 33.0)
    sim = Simulation.from_positions(scene, pos[None], np.ones(1))
    x0 = sim.positions()[0].mean(0)
    sim.advance(3000)
    v = np.linalg.norm(sim.positions()[0].mean(0) - x0) / sim.time * 60.0
    report("cuda free speed", precision, {"speed_um_per_min": v})
    sim.close()
    assert v == pytest.approx(4.0, rel=0.005)


# ------------------------------------------------------------------ the throughput benchmark's command
def test_bench_throughput_measures_writes_merges_and_projects(tmp_path, capsys):
    """`python -m taichimyxo bench throughput` at a tiny size: a row with a positive rate on the CPU, written to
    CSV and JSON, merged with the rows already in the folder (here S3 and S11 at paper scale, made up), from which
    the full-S3 projection follows: 5.4 M steps (6 h at S3's 4 ms) x 16 000 particles / the rate. Without CUDA,
    --arch cuda is refused in one line (no fallback: a CPU figure is never reported as a GPU's)."""
    import csv
    import json

    from taichimyxo.interface.cli import main
    seed = [{"scene": s, "area": 1.0, "arch": "cpu", "precision": "mixed", "integrator": "explicit",
             "particle_steps_per_s": rate} for s, rate in (("S3", 32e6), ("S11", 8e6))]
    (tmp_path / "throughput.json").write_text(json.dumps({"rows": seed}))
    assert main(["bench", "throughput", "--scenes", "S1", "--sizes", "0.04", "--steps", "10", "--warm", "2",
                 "--threads", "2", "--out", str(tmp_path)]) == 0
    doc = json.loads((tmp_path / "throughput.json").read_text())
    s1 = [r for r in doc["rows"] if r["scene"] == "S1"]
    assert len(s1) == 1 and s1[0]["cells"] == 80 and s1[0]["particles"] == 640 and s1[0]["box_um"] == "40x40"
    assert s1[0]["particle_steps_per_s"] > 0 and s1[0]["arch"] == "cpu" and s1[0]["loop_shape"] == "cpu"
    assert {r["scene"] for r in doc["rows"]} == {"S1", "S3", "S11"}
    with open(tmp_path / "throughput.csv") as f:
        assert len(list(csv.DictReader(f))) == 3
    p = doc["projection_full_S3"]["cpu"]
    assert p["steps"] == 5_400_000 and p["particles"] == 16_000
    assert p["sparse_wall_h"] == pytest.approx(5.4e6 * 16e3 / 32e6 / 3600, rel=1e-3)
    assert p["dense_wall_h"] == pytest.approx(4 * p["sparse_wall_h"], rel=1e-3)
    assert "full 6 h S3 at paper scale on cpu: 45.0 min" in capsys.readouterr().out
    if _no_cuda_reason():
        assert main(["bench", "throughput", "--arch", "cuda", "--sizes", "1", "--out", str(tmp_path)]) == 2
        assert "no fallback" in capsys.readouterr().err
