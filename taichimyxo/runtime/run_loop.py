"""The run loop: advance a simulation with writers attached (taichimyxo.io.writers), in the way HOOMD-blue's
``Simulation.run`` calls the writers whose triggers fire.

:func:`drive` advances the simulation in chunks (at most ``chunk_steps`` steps) to the next event and

- at every step a writer's step trigger fires (:class:`taichimyxo.runtime.triggers.Periodic`), and at the last step for
  writers with ``final=True``, makes one Frame and hands it to those writers, and to the writers with no trigger
  (the invariant check), which see every frame;
- opens the speed window before each frame: the displayed speed is a displacement over the scene's
  ``run.speed_window_s`` ending at the frame, or, when frames are closer together than that, over the time since
  the previous frame (docs/model.md). The window is fixed by the schedule alone (not by where a run started), so a
  resumed run measures the same speeds as an uninterrupted one;
- after every chunk calls each writer's ``after_chunk`` (progress line, invariants between frames) and asks the
  other triggers (:class:`taichimyxo.runtime.triggers.WallClock`: checkpoints) whether they fire;
- stops cleanly on SIGINT/SIGTERM (``catch_signals``: the chunk finishes, status "interrupted");
- rolls back on a broken invariant or a neighbour-list overflow (``rollback``, docs/model.md "Numerics"): the
  state is copied on the device before every chunk (never to the host), and a chunk that breaks one is redone
  from that copy with each scene step split into 2 (then 4, 8) shorter steps; the scene's step resumes after it.
  Writers see no frame of the broken attempt. When the shortest split breaks too, or with ``rollback=False``, the
  run stops (status "failed", ``Run.broken`` says why, ``Run.gave_up`` after rollbacks, the state back at the last
  good copy);
- closes every writer (any status), then calls each writer's ``finish`` (what depends on how the run ended: the
  checkpoint, the last-frame panel, the summary).
"""
from __future__ import annotations

import errno
import signal
import time

from .triggers import is_step_trigger


class InvariantBroken(RuntimeError):
    """The state broke a numerical invariant: the step is too large for the configuration (or the model blew up)."""


MAX_SPLIT = 8        # a chunk whose scene steps split into 8 still breaks an invariant: the run stops there


class Interrupt:
    """SIGINT/SIGTERM set a flag; the loop finishes its chunk, closes the files and checkpoints."""

    def __init__(self):
        self.signum = None
        self._old = {}

    def __enter__(self):
        for s in (signal.SIGINT, signal.SIGTERM):
            try:
                self._old[s] = signal.signal(s, self._handle)
            except ValueError:      # not the main thread
                pass
        return self

    def _handle(self, signum, frame):
        if self.signum is not None:       # a second Ctrl-C: stop now
            raise KeyboardInterrupt
        self.signum = signum

    def request(self, signum) -> None:
        """Stop after the current chunk, as if `signum` had come (a no-op when a stop is already asked for)."""
        if self.signum is None:
            self.signum = signum

    def __exit__(self, *exc):
        for s, h in self._old.items():
            signal.signal(s, h)


# a write that failed for want of space (a full disk, a quota, a file-size limit): the run stops, keeping what it wrote
NO_SPACE = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def no_space(e: BaseException) -> bool:
    return isinstance(e, OSError) and e.errno in NO_SPACE


class Run:
    """One call of :func:`drive`: the simulation, its writers and how the run went. Writers read it.

    status: "running", then "completed", "interrupted" or "failed" (broken: why). frame: the Frame of the current
    step (made once per step, on first use). full_window: the current frame's speeds were averaged over the full
    speed window. last_frame: the last frame handed to writers. wall_seconds: from the start until every writer
    was closed. steps_done: steps advanced in this call. gave_up: the run stopped after rolling back to the
    same place with every split (sim.rollbacks lists the rollbacks). wall_by_hour: wall seconds this call spent
    advancing each simulated hour (index = hour, writers included), which shows how a run's cost grows as its
    state forms (docs/performance.md)."""

    def __init__(self, sim, writers, end_step: int):
        self.sim, self.writers = sim, writers
        self.start_step, self.end_step = sim.step_count, end_step
        self.status, self.broken, self.gave_up = "running", None, False
        self.steps_done, self.wall_seconds = 0, 0.0
        self.wall_by_hour: list[float] = []
        self.full_window = False
        self.last_frame = None
        self._frame = None

    @property
    def step(self) -> int:
        return self.sim.step_count

    @property
    def completed(self) -> bool:
        return self.status == "completed"

    @property
    def frame(self):
        if self._frame is None or self._frame.step != self.sim.step_count:
            fr = self.sim.frame()
            fr.meta.setdefault("scene", self.sim.scene.name)
            self._frame = fr
        return self._frame


def steps_for(sim, seconds=None, minutes=None, hours=None, steps=None) -> int:
    """Steps of the scene's time step in the given simulated time (rounded to whole steps), or `steps`."""
    given = [v is not None for v in (seconds, minutes, hours, steps)]
    if sum(given) != 1:
        raise ValueError("give exactly one of seconds=, minutes=, hours=, steps=")
    if steps is not None:
        return int(steps)
    t = seconds if seconds is not None else (minutes * 60.0 if minutes is not None else hours * 3600.0)
    return int(round(t / sim.scene.dt))


class SpeedWindow:
    """The displayed speed's window (module docstring): where it opens before a frame, and whether a frame's speeds
    cover all of it. The step it opened at is the simulation's own (sim.speed_window_start, kept in checkpoints),
    so a run continued in a notebook or resumed from a checkpoint knows whether the coming frame's window is open."""

    def __init__(self, sim, seconds: float, stepped: list, start_step: int):
        self.sim, self.seconds, self.stepped, self.start_step = sim, seconds, stepped, start_step
        self.dt = sim.scene.dt
        self.steps = max(1, int(round(seconds / self.dt)))
        self.forced = -1              # where this run opened a window the schedule did not

    def start_for(self, F: int) -> int:
        """The step the window of the frame at F opens: a window back, but not before the previous frame."""
        prev = max([w.trigger.prev_before(F) for w in self.stepped], default=self.start_step)
        return max(F - self.steps, prev)

    def full(self, F: int) -> bool:
        """The speeds of the frame at F are averaged over the full window."""
        ws = max(self.start_for(F), self.forced) if F > 0 else F
        return F > 0 and (F - ws) * self.dt >= self.seconds - 0.5 * self.dt

    def open(self) -> None:
        self.sim.snapshot_speed()

    def open_if_missing(self, F) -> None:
        """A run that starts inside the coming frame's window this simulation did not open opens one now."""
        step = self.sim.step_count
        if F is not None and self.start_for(F) < step < F and self.sim.speed_window_start != self.start_for(F):
            self.open()
            self.forced = step


def drive(sim, n_steps: int, writers=(), *, chunk_steps: int = 2000, speed_window_s: float | None = None,
          catch_signals: bool = True, stop_after_steps: int | None = None, close: bool = True,
          rollback: bool = True) -> Run:
    """Advance `sim` by `n_steps` steps of the scene's time step with `writers` attached; returns the :class:`Run`.

    speed_window_s: the displayed speed's window (default: the scene's run.speed_window_s). catch_signals: SIGINT
    and SIGTERM end the run after the current chunk (status "interrupted") instead of raising KeyboardInterrupt.
    stop_after_steps (tests): behave as if interrupted after that many steps. close: close the writers at the end
    (False keeps them open for a next call; ``finish`` is called either way). rollback: redo a chunk that breaks an
    invariant at split steps (module docstring); False stops the run at the first breach."""
    from ..physics.neighbours import NeighbourOverflow
    if not (hasattr(sim, "advance") and hasattr(sim, "scene")):        # a Simulation (not imported: no cycle)
        raise TypeError(f"drive(sim, n_steps): expected a Simulation, e.g. tm.Simulation(tm.load_scene('S3')); got "
                        f"{type(sim).__name__}")
    if isinstance(n_steps, bool) or not isinstance(n_steps, (int,)) and not hasattr(n_steps, "__index__") \
            or int(n_steps) < 0:
        raise ValueError(f"drive(sim, n_steps = {n_steps!r}): expected a whole number of steps >= 0, e.g. 1000")

    dt = sim.scene.dt
    writers = sorted(writers, key=lambda w: getattr(w, "order", 0))      # the invariant check first, summary last
    for w in writers:
        if w.trigger is not None:
            w.trigger.bind(dt)
    stepped = [w for w in writers if is_step_trigger(w.trigger)]
    polled = [w for w in writers if w.trigger is not None and not is_step_trigger(w.trigger)]
    riders = [w for w in writers if w.trigger is None]
    finals = [w for w in writers if getattr(w, "final", False)]
    run = Run(sim, writers, sim.step_count + int(n_steps))
    end = run.end_step
    window = SpeedWindow(sim, sim.scene.speed_window_s if speed_window_s is None else speed_window_s, stepped,
                         run.start_step)

    def next_event(step):
        cands = [w.trigger.next_after(step) for w in stepped]
        if finals and step < end:
            cands.append(end)
        return min(cands) if cands else None

    def event(F):
        due = [w for w in writers if (w in stepped and w.trigger(F)) or (w in finals and F == end) or w in riders]
        if not any(w not in riders for w in due):
            return
        run.full_window = window.full(F)
        for w in due:
            w.write(run)
        run.last_frame = run.frame

    def advance_chunk(n, F):
        """n steps, the frame at F if they reach it, the writers' after_chunk; rolled back and redone at split
        steps when they break an invariant."""
        snapshot = sim.take_snapshot() if rollback else None
        split, redone = 1, []
        hour, t0 = int(sim.time // 3600.0), time.perf_counter()
        while True:
            try:
                sim.advance(n) if split == 1 else sim.advance_split(n, split)
                run.steps_done += n
                if sim.step_count == F:
                    event(F)
                for w in writers:
                    w.after_chunk(run)
                run.wall_by_hour.extend([0.0] * (hour + 1 - len(run.wall_by_hour)))
                run.wall_by_hour[hour] += time.perf_counter() - t0
                return
            except (InvariantBroken, NeighbourOverflow) as e:
                if snapshot is None:
                    raise
                sim.restore_snapshot(snapshot)
                sim.rollbacks.extend(redone)            # the copy predates this chunk's rollbacks
                run._frame = None
                run.steps_done = sim.step_count - run.start_step
                if split >= MAX_SPLIT:
                    run.gave_up = True
                    raise InvariantBroken(f"{e}; rolled back to {sim.time:.6g} s and redone with the step split "
                                          f"into 2, 4 and {MAX_SPLIT}, it breaks again there") from e
                split *= 2
                redone.append((sim.step_count, sim.time, split))
                sim.rollbacks.append(redone[-1])

    wall0 = time.perf_counter()
    try:
        with (Interrupt() if catch_signals else _NoInterrupt()) as intr:
            for w in writers:
                w.start(run)          # the progress line appears once signals are caught
            if sim.step_count == 0:
                event(0)
            window.open_if_missing(next_event(sim.step_count))
            while sim.step_count < end:
                step = sim.step_count
                F = next_event(step)
                target = end
                if F is not None:
                    ws = window.start_for(F)
                    if step == ws:
                        window.open()
                    target = min(end, ws if step < ws else F)
                n = min(target - step, chunk_steps)
                if stop_after_steps is not None:
                    n = min(n, max(0, stop_after_steps - run.steps_done))
                advance_chunk(n, F)
                if intr.signum is not None or (stop_after_steps is not None and run.steps_done >= stop_after_steps):
                    run.status = "interrupted"
                    break
                for w in polled:
                    if w.trigger(sim.step_count):
                        w.write(run)
            else:
                run.status = "completed"
    except (InvariantBroken, NeighbourOverflow) as e:
        # NeighbourOverflow: more neighbours than the list holds, which a blown-up state produces
        run.status, run.broken = "failed", str(e)
    except OSError as e:
        if not no_space(e):
            raise
        # the files keep what was written before; --resume continues from the last checkpoint (scene_run.py)
        run.status, run.broken = "no_space", f"{e.strerror} writing {e.filename or 'an output file'}"
    finally:
        if close:
            close_writers(writers, tolerate=no_space if run.status == "no_space" else None)
    run.wall_seconds = time.perf_counter() - wall0
    for w in writers:
        try:
            w.finish(run)
        except OSError as e:
            if not no_space(e):
                raise
            run.status = "no_space"
            run.broken = run.broken or f"{e.strerror} writing {e.filename or 'an output file'}"
    return run


class _NoInterrupt:
    signum = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        pass


def close_writers(writers, tolerate=None) -> None:
    """Close every writer, even when one of them fails to close (the first error is raised after, unless
    `tolerate(error)` says it is one the run already stopped for)."""
    err = None
    for w in writers:
        try:
            w.close()
        except BaseException as e:      # noqa: BLE001 - re-raised below, after the others are closed
            if tolerate is not None and tolerate(e):
                continue
            err = err or e
    if err is not None:
        raise err
