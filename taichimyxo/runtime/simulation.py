"""The Simulation: a scene's state, force field (its terms) and integrator, built once, and what is measured from it.

    sim = Simulation(scene)             # Taichi started, fields for what the scene uses, cells placed by its start
    sim = Simulation.from_positions(scene, positions, engine_direction)    # or at given positions
    sim = Simulation.from_checkpoint(scene, "out/S3.ckpt.npz")             # or at a checkpoint's state
    sim.advance(steps, dt=None)         # advance, no writers (dt in s; the scene's step by default)
    sim.run(minutes=5, writers=[...])       # run simulated time with writers attached (taichimyxo/runtime/run_loop.py)
    sim.frame()                         # a Frame: numpy arrays, what writers and analysis see

Composition (docs/model.md for every equation): State (state.py) holds the particles; NeighbourList
(neighbours.py) the list and its skin check; Model (model.py) composes the units of taichimyxo/physics/terms/ the scene
turns on; the integrator (taichimyxo/physics/integrators/) owns the step. Each is told at construction what the scene
uses, and kernels branch with `ti.static`, so a disabled effect is absent from the compiled code and its fields are
never allocated. One Simulation per process compiles its kernels once; a second instance compiles again.

Determinism: every force is gathered, never scattered, over sorted neighbour lists; the only atomics are in the
list build (sorted afterwards), the slime claim (max of cell index, a fixed rule) and flags. 1 and 2 threads give
bit-identical runs, and a resumed run equals an uninterrupted one. How the kernels launch their loops (serial or
parallel, the scans) is the arch's loop shape, taichimyxo/runtime/launch.py.
"""

from __future__ import annotations

import numpy as np
import taichi as ti

from ..io.frame import Frame
from ..io.scene import SceneError
from ..physics.integrators import imex_options, make_integrator, needs_rebuild, records_contacts
from ..physics.model import Model, field_bytes, fields_of
from ..physics.neighbours import NeighbourList, NeighbourOverflow  # noqa: F401  (NeighbourOverflow: API)
from ..physics.state import Layout, State, list_capacities
from . import backend
from .launch import shape_for

# arguments of the other starts, and the imex integrator's options (integrators/imex.py)
OTHER_STARTS = {"positions": "Simulation.from_positions(scene, positions, engine_direction)",
                "engine_direction": "Simulation.from_positions(scene, positions, engine_direction)",
                "checkpoint": "Simulation.from_checkpoint(scene, checkpoint)"}
IMEX_OPTIONS = ("contacts", "tol", "max_iter", "iters_per_launch")


def check_options(scene, options: dict) -> None:
    """A misplaced argument names the call that takes it (TypeError, one sentence)."""
    from ..io.scene import Scene
    if not isinstance(scene, Scene):
        got = type(scene).__name__ + (f" {scene!r}" if isinstance(scene, str) else "")
        raise TypeError(f"Simulation(scene): expected a Scene, e.g. tm.load_scene('S3'); got {got}")
    for k in options:
        if k in OTHER_STARTS:
            raise TypeError(f"Simulation(scene, {k}=...): a start from given cells is {OTHER_STARTS[k]}")
        if k not in IMEX_OPTIONS:
            raise TypeError(f"Simulation(scene, {k}=...): unknown option; Simulation takes arch, threads, loop_shape "
                            f"and, with run.integrator = 'imex', {', '.join(IMEX_OPTIONS)}")
    if options and scene.integrator not in ("imex", "imex-explicit"):
        raise TypeError(f"Simulation(scene, {sorted(options)[0]}=...): an option of run.integrator = 'imex'; this "
                        f"scene's integrator is {scene.integrator!r} (set run.integrator = 'imex' to use it)")


class Simulation:
    def __init__(self, scene, *, arch: str | None = None, threads: int | None = None, loop_shape: str | None = None,
                 _start: tuple | None = None, **integrator_options):
        """The simulation of `scene` with its integrator, cells placed by the scene's start (a density the start
        cannot place is a SceneError, raised before Taichi starts). Taichi is started for the scene's precision on
        `arch` with `threads` (default: as it already runs, else the CPU with all cores or TAICHIMYXO_THREADS).
        loop_shape: "cpu" or "gpu" forces how the kernels launch their loops (taichimyxo/runtime/launch.py; default: the
        arch's). integrator_options go to the integrator (imex: contacts = coupled | diagonal | explicit, tol,
        max_iter). Other starts: from_positions, from_checkpoint."""
        check_options(scene, integrator_options)
        integrator_options = imex_options(scene, integrator_options)      # refused before any field is made
        positions, engine_direction = _start if _start is not None else initial_state(scene)
        self.arch = init_backend(scene, arch, threads)
        self.scene = scene
        self.layout = Layout.from_scene(scene)
        self.step_count = 0
        self.time_offset = 0.0      # simulated time of steps taken at another dt than the scene's, minus their share
        self.writers = []
        self.rollbacks = []         # (step, simulated s, split) of each rollback (run_loop.py), kept in checkpoints
        self.sessions_before = {}   # the wall-time totals a loaded checkpoint stored (writers.checkpoint_totals)
        self._twins, self._twin_tree = None, None       # the rollback's copy of the state, made on first use
        self._closed = False
        backend.simulation_starting()
        builder = ti.FieldsBuilder()
        self.state = State(self.layout, builder, shape_for(self.layout.n_segments, loop_shape))
        self.neighbours = NeighbourList(self.state, builder, scene.width, scene.skin, **list_capacities(scene))
        self.model = Model(scene, self.state, self.neighbours, builder,
                           record_contacts=records_contacts(scene, **integrator_options))
        self.integrator = make_integrator(scene, self.state, self.model, self.neighbours, builder, **integrator_options)
        self._tree = builder.finalize()
        self.set_state(positions, engine_direction)
        self.model.start()

    @classmethod
    def from_positions(cls, scene, positions, engine_direction, **options) -> Simulation:
        """The simulation of `scene` with its cells at `positions`, (n_cells, N, 2) µm, heads by `engine_direction`,
        (n_cells,) ±1 (+1: particle 0 is the head). options: those of Simulation."""
        return cls(scene, _start=(positions, engine_direction), **options)

    @classmethod
    def from_checkpoint(cls, scene, checkpoint, **options) -> Simulation:
        """The simulation of `scene` at the state of `checkpoint` (a path written by writers.Checkpoint, or its
        dict as read_checkpoint returns it; refused, ValueError, when written for another scene)."""
        if not isinstance(checkpoint, dict):
            from ..io.writers import read_checkpoint
            checkpoint = read_checkpoint(checkpoint, scene)
        sim = cls(scene, _start=(checkpoint["x"], checkpoint["ke"]), **options)
        sim.load_checkpoint(checkpoint)
        return sim

    # ------------------------------------------------------------------ sizes
    @property
    def n_p(self) -> int:
        return self.state.n_p

    @property
    def n_s(self) -> int:
        return self.state.n_s

    @property
    def serial(self) -> bool:
        return self.state.serial

    @property
    def rebuilds(self) -> int:
        return self.neighbours.rebuilds

    @property
    def time(self) -> float:
        """Simulated time, s: the scene's steps, corrected for any steps run(n, dt) took at another dt."""
        return self.step_count * self.layout.dt + self.time_offset

    # ------------------------------------------------------------------ state
    def set_state(self, positions, engine_direction, step: int = 0) -> None:
        self.state.load(positions, engine_direction)
        self.step_count = step
        self.time_offset = 0.0
        self.sessions_before = {}
        self.integrator.reset()
        self.snapshot_speed()
        self.neighbours.rebuild()

    def positions(self) -> np.ndarray:
        """(n_cells, N, 2) float64, chains unwrapped, particle 0 in the box."""
        return self.state.positions()

    def wrapped_positions(self) -> np.ndarray:
        """(n_cells * N, 2) positions as stored: wrapped into the box, in position precision."""
        return self.state.x.to_numpy()

    def engine_direction(self) -> np.ndarray:
        return self.state.ke.to_numpy().astype(np.int8)

    def _checkpointed(self) -> dict:
        return {**self.model.checkpoint_fields(), **self.integrator.checkpoint_fields()}

    def get_checkpoint(self) -> dict:
        st = {"x": self.state.x.to_numpy(), "x_snap": self.state.x_snap.to_numpy(), "ke": self.state.ke.to_numpy(),
              "step": np.array(self.step_count), "snap_step": np.array(self.state.snap_step),
              "time_offset": np.array(self.time_offset),
              "rollbacks": np.array(self.rollbacks, dtype=np.float64).reshape(-1, 3)}
        st.update({name: f.to_numpy() for name, f in self._checkpointed().items()})
        return st

    def _state_fields(self) -> dict:
        return {"x": self.state.x, "x_snap": self.state.x_snap, "ke": self.state.ke, **self._checkpointed()}

    def take_snapshot(self) -> dict:
        """Copy the state into twin fields on the device (a rollback's copy, run_loop.py): nothing is copied to the
        host. Returns the scalars the copy needs; restore_snapshot puts both back."""
        fields = self._state_fields()
        if self._twins is None:
            builder = ti.FieldsBuilder()
            self._twins = {name: _twin(f, builder) for name, f in fields.items()}
            self._twin_tree = builder.finalize()
        for name, f in fields.items():
            self._twins[name].copy_from(f)
        return {"step": self.step_count, "snap_step": self.state.snap_step, "time_offset": self.time_offset,
                "rollbacks": list(self.rollbacks)}

    def restore_snapshot(self, snap: dict) -> None:
        for name, f in self._state_fields().items():
            f.copy_from(self._twins[name])
        self.step_count, self.state.snap_step = snap["step"], snap["snap_step"]
        self.time_offset, self.rollbacks = snap["time_offset"], list(snap["rollbacks"])
        self.integrator.reset(restored=True)
        self.neighbours.rebuild()

    def load_checkpoint(self, st: dict) -> None:
        self.state.x.from_numpy(st["x"])
        self.state.ke.from_numpy(st["ke"])
        self.step_count = int(st["step"])
        self.time_offset = float(st["time_offset"]) if "time_offset" in st else 0.0
        done = np.asarray(st["rollbacks"]) if "rollbacks" in st else np.zeros((0, 3))
        self.rollbacks = [(int(a), float(b), int(c)) for a, b, c in done]
        from ..io.writers import checkpoint_totals
        self.sessions_before = checkpoint_totals(st)
        added_later = self.model.added_later()
        for name, f in self._checkpointed().items():
            if name in st or name not in added_later:
                f.from_numpy(st[name])
        self.state.x_snap.from_numpy(st["x_snap"])
        self.state.snap_step = int(st["snap_step"])
        self.integrator.reset(restored=True)
        self.neighbours.rebuild()

    # ------------------------------------------------------------------ driving
    def advance(self, n_steps: int, dt: float | None = None) -> None:
        """Advance n_steps steps of dt seconds (the scene's step by default), with no writer: run() is the same
        with writers attached.
        The neighbour list stays valid because every step checks every particle's real displacement since the list
        was built, and the list is rebuilt as soon as one has moved half the skin: then, at every force evaluation,
        no two particles have closed in by more than the skin since the build, whatever their speed (a guided head
        swings at up to F_max / zeta_n ~ 32 v_b; an interval chosen for an assumed top speed is no guarantee).
        The check costs one comparison per particle inside the step kernel, which returns the flag.
        With run.step_control = "error" (and dt not given) n_steps counts scene steps, and the controller chooses
        how many of them each step covers (taichimyxo/physics/integrators/step_control.py)."""
        step = self.integrator.step
        control = getattr(self.integrator, "control", None)
        if control is not None and dt is None:
            left = n_steps
            while left > 0:
                m = control.next_step(left)
                self.step_count += m
                left -= m
                if control.took(step(m * self.layout.dt), m):     # decodes the step code
                    self.neighbours.rebuild()
            return
        dt = self.layout.dt if dt is None else dt
        if dt != self.layout.dt:
            self.time_offset += n_steps * (dt - self.layout.dt)
        for _ in range(n_steps):
            self.step_count += 1
            if needs_rebuild(step(dt)):
                self.neighbours.rebuild()

    def advance_split(self, n_steps: int, split: int) -> None:
        """Advance n_steps scene steps, each taken as `split` steps of dt / split (a rollback's redo, run_loop.py):
        the step count, frames and reversal clocks still count scene steps."""
        dt = self.layout.dt / split
        step = self.integrator.step
        for _ in range(n_steps):
            self.step_count += 1
            for k in range(split):
                self.model.hold_clocks(k < split - 1)
                if needs_rebuild(step(dt)):
                    self.neighbours.rebuild()

    def attach(self, writer) -> None:
        """Attach a writer (taichimyxo.io.writers): run calls it whenever its trigger fires."""
        self.writers.append(writer)

    def run(self, *, seconds=None, minutes=None, hours=None, steps=None, writers=(), progress: bool = False,
            **options):
        """Run for simulated time (one of seconds, minutes, hours, on the scene's step grid) or steps, with the
        attached writers and `writers` (taichimyxo.runtime.run_loop.drive; options: catch_signals, chunk_steps,
        rollback, ...). progress: show the progress line. `writers` are closed at the end; attached ones stay open for
        the next call and are closed by close(). Returns the run loop's Run (status "completed", or "interrupted" after
        Ctrl-C, or
        "failed" with Run.broken naming a broken invariant)."""
        from .run_loop import close_writers, drive, steps_for
        n = steps_for(self, seconds, minutes, hours, steps)
        extra = list(writers)
        if progress:
            from ..io.writers import ProgressLine
            extra.insert(0, ProgressLine(self.scene.name, self.step_count + n))
        run = drive(self, n, [*self.writers, *extra], close=False, **options)
        close_writers(extra)
        return run

    # ------------------------------------------------------------------ measurements
    def snapshot_speed(self) -> None:
        """Start a speed window: the displayed speed is |x(t) - x(t - window)| / window (docs/model.md)."""
        self.state.snapshot(self.step_count)

    @property
    def speed_window_start(self) -> int:
        """The step the current speed window opened at (snapshot_speed)."""
        return self.state.snap_step

    def particle_speed(self) -> np.ndarray:
        """(n_cells, N) µm/min averaged since the last snapshot_speed."""
        return self.state.speed_since_snapshot(self.step_count, self.layout.dt)

    def particle_velocity(self) -> np.ndarray:
        """(n_cells, N, 2) µm/min averaged since the last snapshot_speed (the vectors whose norms particle_speed
        gives: what a rotation is fitted to)."""
        return self.state.velocity_since_snapshot(self.step_count, self.layout.dt)

    def segment_strain(self) -> np.ndarray:
        """(n_cells, N-1) strain energy in J. Only in scenes that ask for strain (output.strain)."""
        if self.model.strain is None:
            raise RuntimeError("strain energy is not computed in this scene (set output.strain = true)")
        return self.model.strain.segment_strain()

    def frame(self) -> Frame:
        return Frame(time_s=self.time, step=self.step_count, box=self.scene.box, width_um=self.scene.width,
                     positions=self.positions(), engine_direction=self.engine_direction(),
                     particle_speed=self.particle_speed(), particle_velocity=self.particle_velocity(),
                     segment_strain=self.segment_strain() if self.model.strain is not None else None,
                     meta={"scene": self.scene.name})

    def forces(self) -> dict:
        """Forces at the current state without stepping (Model.forces): internal, contact, total, tangent."""
        return self.model.forces()

    def solver_stats(self) -> dict:
        return self.integrator.stats()

    def reset_stats(self) -> None:
        if hasattr(self.integrator, "reset_stats"):
            self.integrator.reset_stats()

    def allocated_fields(self) -> dict:
        """Name -> bytes of every field this Simulation allocated (effects a scene does not use are absent)."""
        parts = [self.state, self.neighbours, *self.model.units, self.integrator]
        if hasattr(self.integrator, "band"):
            parts.append(self.integrator.band)
        out = {}
        for part in parts:
            out.update({k: field_bytes(f) for k, f in fields_of(part).items()})
        return out

    def close(self) -> None:
        if self.writers:
            from .run_loop import close_writers
            close_writers(self.writers)
            self.writers = []
        self.model.close()
        if self._tree is not None:
            self._tree.destroy()
            self._tree = None
        if self._twin_tree is not None:
            self._twin_tree.destroy()
            self._twins, self._twin_tree = None, None
        if not self._closed:
            self._closed = True
            backend.simulation_closed()


def _twin(f, builder):
    """A field of f's type and shape, placed by builder."""
    if isinstance(f, ti.MatrixField):
        t = ti.Vector.field(f.n, f.dtype) if f.ndim == 1 else ti.Matrix.field(f.n, f.m, f.dtype)
    else:
        t = ti.field(f.dtype)
    builder.dense(ti.axes(*range(len(f.shape))), f.shape).place(t)
    return t


def initial_state(scene, progress=None):
    """(positions, engine_direction) placed by the scene's start, before Taichi starts: a density the start cannot
    place is a SceneError. progress: called (placed, n, tries) while placing."""
    from ..physics.placement import PlacementError, initial_configuration
    try:
        return initial_configuration(scene, progress=progress)
    except PlacementError as e:
        raise SceneError(f"population: the {scene.start!r} start cannot place the cells ({e}); lower "
                         f"population.density_cells_per_cm2 or population.cells, or enlarge the domain"
                         f"{scene.preview_note()}") from None


def init_backend(scene, arch: str | None = None, threads: int | None = None) -> str:
    """Taichi for the scene's precision on `arch` with `threads` (None, None: as it already runs, else the CPU with
    all cores or TAICHIMYXO_THREADS); an unavailable GPU falls back to the CPU. Returns the arch used."""
    return backend.ensure(arch, threads, default_fp="f64" if scene.precision == "f64" else None)
