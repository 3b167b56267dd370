"""The Simulation: a scene's state, force field (its terms) and integrator, built once, and what is measured from it.

    sim = Simulation(scene)             # fields for what the scene uses, initial configuration from the scene
    sim.run(steps, dt=None)             # advance (dt in s; the scene's step by default)
    sim.run_for(minutes=5, writers=[])  # advance simulated time with writers attached (taichimyxo/driver.py)
    sim.frame()                         # a Frame: numpy arrays, what writers and analysis see

Composition (docs/model.md for every equation): State (state.py) holds the particles; NeighbourList
(neighbours.py) the list and its skin check; Model (model.py) composes the units of taichimyxo/terms/ the scene turns
on; the integrator (taichimyxo/integrators/) owns the step. Each is told at construction what the scene uses, and
kernels branch with `ti.static`, so a disabled effect is absent from the compiled code and its fields are never
allocated. One Simulation per process compiles its kernels once; a second instance compiles again.

Determinism: every force is gathered, never scattered, over sorted neighbour lists; the only atomics are in the
list build (sorted afterwards), the slime claim (max of cell index, a fixed rule) and flags. 1 and 2 threads give
bit-identical runs, and a resumed run equals an uninterrupted one. How the kernels launch their loops (serial or
parallel, the scans) is the arch's loop shape, taichimyxo/launch.py.
"""

import numpy as np
import taichi as ti

from . import backend
from .frame import Frame
from .integrators import make_integrator, records_contacts
from .launch import shape_for
from .model import Model, field_bytes, fields_of
from .neighbours import NeighbourList, NeighbourOverflow  # noqa: F401  (NeighbourOverflow: API)
from .state import Layout, State, list_capacities

# checkpoint fields newer than some checkpoints: an older checkpoint without them leaves them at 0
ADDED_LATER = ("rev_suppressed",)


class Simulation:
    def __init__(self, scene, positions: np.ndarray | None = None, engine_direction: np.ndarray | None = None,
                 loop_shape: str | None = None, **integrator_options):
        """Build fields for `scene` and load the initial configuration (from the scene's start unless positions,
        (n_cells, N, 2) µm, and engine_direction, (n_cells,) ±1, are given). loop_shape: "cpu" or "gpu" forces how the
        kernels launch their loops (taichimyxo/launch.py; default: the arch's). integrator_options go to the
        integrator (imex: contacts = coupled | diagonal | explicit, tol, max_iter)."""
        self.scene = scene
        self.layout = Layout.from_scene(scene)
        self.step_count = 0
        self.time_offset = 0.0      # simulated time of steps taken at another dt than the scene's, minus their share
        self.writers = []
        self.rollbacks = []         # (step, simulated s, split) of each rollback (driver.py), kept in checkpoints
        self._twins, self._twin_tree = None, None       # the rollback's copy of the state, made on first use
        self._closed = False
        backend.simulation_starting()
        fb = ti.FieldsBuilder()
        self.state = State(self.layout, fb, shape_for(self.layout.n_segments, loop_shape))
        self.neighbours = NeighbourList(self.state, fb, scene.width, scene.skin, **list_capacities(scene))
        self.model = Model(scene, self.state, self.neighbours, fb,
                           record_contacts=records_contacts(scene, **integrator_options))
        self.integrator = make_integrator(scene, self.state, self.model, self.neighbours, fb, **integrator_options)
        self._tree = fb.finalize()
        if positions is None:
            from .init import initial_configuration
            positions, engine_direction = initial_configuration(scene)
        self.set_state(positions, engine_direction)
        if self.model.reversals is not None:
            self.model.reversals.start()

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
        """Copy the state into twin fields on the device (a rollback's copy, driver.py): nothing is copied to the
        host. Returns the scalars the copy needs; restore_snapshot puts both back."""
        fields = self._state_fields()
        if self._twins is None:
            fb = ti.FieldsBuilder()
            self._twins = {name: _twin(f, fb) for name, f in fields.items()}
            self._twin_tree = fb.finalize()
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
        for name, f in self._checkpointed().items():
            if name in st or name not in ADDED_LATER:
                f.from_numpy(st[name])
        self.state.x_snap.from_numpy(st["x_snap"])
        self.state.snap_step = int(st["snap_step"])
        self.integrator.reset(restored=True)
        self.neighbours.rebuild()

    # ------------------------------------------------------------------ driving
    def run(self, n_steps: int, dt: float | None = None) -> None:
        """Advance n_steps steps of dt seconds (the scene's step by default).
        The neighbour list stays valid because every step checks every particle's real displacement since the list
        was built, and the list is rebuilt as soon as one has moved half the skin: then, at every force evaluation,
        no two particles have closed in by more than the skin since the build, whatever their speed (a guided head
        swings at up to F_max / zeta_n ~ 32 v_b; an interval chosen for an assumed top speed is no guarantee).
        The check costs one comparison per particle inside the step kernel, which returns the flag.
        With run.step_control = "error" (and dt not given) n_steps counts scene steps, and the controller chooses
        how many of them each step covers (taichimyxo/integrators/step_control.py)."""
        step = self.integrator.step
        control = getattr(self.integrator, "control", None)
        if control is not None and dt is None:
            left = n_steps
            while left > 0:
                m = control.next_step(left)
                self.step_count += m
                left -= m
                if control.took(step(m * self.layout.dt), m):
                    self.neighbours.rebuild()
            return
        dt = self.layout.dt if dt is None else dt
        if dt != self.layout.dt:
            self.time_offset += n_steps * (dt - self.layout.dt)
        for _ in range(n_steps):
            self.step_count += 1
            if step(dt) & 1:
                self.neighbours.rebuild()

    def run_split(self, n_steps: int, split: int) -> None:
        """Advance n_steps scene steps, each taken as `split` steps of dt / split (a rollback's redo, driver.py):
        the step count, frames and reversal clocks still count scene steps."""
        dt = self.layout.dt / split
        reversals = self.model.reversals
        step = self.integrator.step
        for _ in range(n_steps):
            self.step_count += 1
            for k in range(split):
                if reversals is not None:
                    reversals.hold_clock(k < split - 1)
                if step(dt) & 1:
                    self.neighbours.rebuild()

    def attach(self, writer) -> None:
        """Attach a writer (taichimyxo.writers): run_for calls it whenever its trigger fires."""
        self.writers.append(writer)

    def run_for(self, seconds=None, minutes=None, hours=None, steps=None, writers=(), **options):
        """Advance by simulated time (one of seconds, minutes, hours, on the scene's step grid) or steps, with the
        attached writers and `writers` (taichimyxo.driver.drive; options: catch_signals, chunk_steps, ...). Attached
        writers stay open for the next call and are closed by close(). Returns the driver's Run."""
        from .driver import close_writers, drive, steps_for
        run = drive(self, steps_for(self, seconds, minutes, hours, steps), [*self.writers, *writers], close=False,
                    **options)
        close_writers(writers)
        return run

    # ------------------------------------------------------------------ measurements
    def snapshot_speed(self) -> None:
        """Start a speed window: the displayed speed is |x(t) - x(t - window)| / window (docs/model.md)."""
        self.state.snapshot(self.step_count)

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
            from .driver import close_writers
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


def _twin(f, fb):
    """A field of f's type and shape, placed by fb."""
    if isinstance(f, ti.MatrixField):
        t = ti.Vector.field(f.n, f.dtype) if f.ndim == 1 else ti.Matrix.field(f.n, f.m, f.dtype)
    else:
        t = ti.field(f.dtype)
    fb.dense(ti.axes(*range(len(f.shape))), f.shape).place(t)
    return t


def make_simulation(scene, **kw) -> Simulation:
    """The scene's Simulation (its integrator chosen by run.integrator). Kept for callers of the former API."""
    return Simulation(scene, **kw)
