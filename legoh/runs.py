"""Run bookkeeping shared by the training stages: the frame budget left to a resumed run,
a clean stop on SIGINT / SIGTERM, a lock on the run folder, where a resumed run writes,
MuJoCo's log and a word when simulations diverge.

Kept apart from the loops (``legoh/train/``) so each rule is one small function a test can
call, and the loops only ask it.
"""

from __future__ import annotations

import contextlib
import os
import shlex
import signal
import threading
import warnings
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None


def iterations_left(start: int, iterations: int, frames_per_batch: int, total_frames: int,
                    resume: str | None) -> int:
    """Iterations still to run for a run resumed at iteration ``start`` of ``iterations``.

    A checkpoint already at or past the budget (``algo.total_frames`` lowered on resume)
    means "no more frames": 0, said in a message, where the raw difference would be a
    negative frame budget, which torchrl's collector reads as "collect forever".
    """
    left = iterations - start
    if left <= 0 and resume:
        print(f"[legoh] {resume} is at iteration {start} ({start * frames_per_batch} frames), "
              f"which already meets algo.total_frames={total_frames} ({iterations} "
              f"iteration(s) of {frames_per_batch} frames): no more frames to collect; pass "
              f"algo.total_frames above {start * frames_per_batch} to train on")
    return max(0, left)


class GracefulStop:
    """SIGINT / SIGTERM during training: finish the iteration under way, then stop cleanly.

    Killing a run mid-iteration lost everything since its last periodic checkpoint and left
    an MCAP segment without its summary (unreadable to the stock ``mcap`` reader). Inside
    ``with GracefulStop() as stop`` the first signal only sets :attr:`signum`;
    :meth:`batches` then ends the loop after the current iteration, the trainer writes its
    checkpoint and closes its logs, and :meth:`exit_if_signalled` prints how to resume and
    exits with 128 + the signal number. A second signal raises ``KeyboardInterrupt`` at once.
    Handlers are installed only in the main thread (Python allows no other); the previous
    ones come back on exit, so nested stages (stage 2 training its oracle) nest.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.signum: int | None = None
        self._previous: dict[int, object] = {}

    def __enter__(self) -> GracefulStop:
        if threading.current_thread() is threading.main_thread():
            for sig in self.SIGNALS:
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()

    def _handle(self, signum: int, frame: object) -> None:
        if self.signum is not None:
            raise KeyboardInterrupt(f"second {signal.Signals(signum).name}: stopping at once")
        self.signum = signum
        print(f"\n[legoh] {signal.Signals(signum).name}: finishing this iteration, then a "
              f"checkpoint (send it again to stop at once, losing the iteration)", flush=True)

    def batches(self, collector: Iterable) -> Iterator:
        """``collector``'s batches until a signal came (checked after each iteration)."""
        for batch in collector:
            yield batch
            if self.signum is not None:
                return

    def exit_if_signalled(self, checkpoint: Path, hint: str | None = None) -> None:
        """After the trainer saved ``checkpoint`` and closed its logs: say how to resume
        (``hint``, default :func:`resume_command`) and exit with 128 + the signal number."""
        if self.signum is None:
            return
        name = signal.Signals(self.signum).name
        print(f"[legoh] stopped by {name}: checkpoint {checkpoint}, logs closed. Resume with:\n"
              f"    {hint or resume_command(checkpoint)}", flush=True)
        raise SystemExit(128 + self.signum)


def resume_command(checkpoint: Path | None) -> str:
    """``python run.py <this run's overrides> resume=<checkpoint>``: the command that
    continues this run (outside Hydra the overrides are unknown: only ``resume=``). With no
    checkpoint: this run's own command without ``resume=``."""
    from hydra.core.hydra_config import HydraConfig

    args = []
    if HydraConfig.initialized():
        args = [o for o in HydraConfig.get().overrides.task if not o.startswith("resume=")]
    tail = [] if checkpoint is None else [f"resume={checkpoint}"]
    return shlex.join(["python", "run.py", *args, *tail])


class RunFolderBusy(RuntimeError):
    """Another live process holds the run folder's lock."""


LOCK_NAME = ".legoh.lock"


@contextlib.contextmanager
def run_lock(folder: Path) -> Iterator[Path]:
    """Hold an exclusive lock on ``folder`` (``.legoh.lock`` in it) while a run writes there.

    Two runs into one folder interleaved their CSV rows and checkpoints; the second one is
    now refused at once, naming the folder and the holder's pid. ``flock`` dies with its
    process (a killed run leaves no stale lock) and conflicts between any two opens, in one
    process or two. Where ``fcntl`` is missing (Windows) nothing is locked.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOCK_NAME
    with path.open("a+") as f:
        if fcntl is not None:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                f.seek(0)
                holder = f.read().strip() or "?"
                raise RunFolderBusy(f"{folder} is in use by another run (pid {holder}); wait "
                                    f"for it, or write elsewhere (hydra.run.dir=...)") from None
        f.seek(0)
        f.truncate()
        f.write(f"{os.getpid()}\n")
        f.flush()
        try:
            yield path
        finally:
            if fcntl is not None:
                fcntl.flock(f, fcntl.LOCK_UN)


@contextlib.contextmanager
def file_lock(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``path``, waiting while another open holds it.

    For a short read-modify-write of one shared file (a run folder's ``teacher.json``):
    the second process waits and then reads what the first wrote, where :func:`run_lock`
    refuses it. Where ``fcntl`` is missing (Windows) nothing is locked.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a+") as f:
        if fcntl is not None:
            fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            if fcntl is not None:
                fcntl.flock(f, fcntl.LOCK_UN)


def wait_for_run(folder: Path) -> bool:
    """Block while another run holds ``folder``'s lock (:func:`run_lock`); True if one did.

    A shared lock waits for the holder's exclusive one and is dropped at once: the folder
    is only read afterwards (a stage-2 job reusing the oracle another job trained there).
    """
    path = Path(folder) / LOCK_NAME
    if fcntl is None or not path.is_file():
        return False
    with path.open("r") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_SH | fcntl.LOCK_NB)
            waited = False
        except BlockingIOError:
            holder = f.read().strip() or "?"
            print(f"[legoh] {folder} is in use by another run (pid {holder}): waiting for it",
                  flush=True)
            fcntl.flock(f, fcntl.LOCK_SH)
            waited = True
        fcntl.flock(f, fcntl.LOCK_UN)
    return waited


def run_folder(mode: str, resume: str | None, hydra_dir: Path,
               hydra_overrides: Sequence[str] = ()) -> Path:
    """The folder a run writes to: Hydra's run folder, except that a resumed training run
    continues in its checkpoint's own folder unless ``hydra.run.dir=`` was given.

    A resume in a fresh folder split one run's history over two folders; in the old folder
    through Hydra it overwrote the first run's ``.hydra/config.yaml``. Here the checkpoint's
    folder gets the rest of the rows (cut back to the checkpoint first: ``ScalarCSV(until=)``)
    and keeps its configs; Hydra's own folder keeps only this command's ``.hydra``.
    """
    explicit = any(o.split("=", 1)[0].lstrip("+~") == "hydra.run.dir" for o in hydra_overrides)
    if mode != "train" or not resume or explicit:
        return hydra_dir
    folder = Path(resume).resolve().parent
    print(f"[legoh] resuming in the checkpoint's run folder {folder} (this command's Hydra "
          f"config: {hydra_dir}; hydra.run.dir=... writes elsewhere)")
    return folder


@contextlib.contextmanager
def mujoco_log_in(folder: Path) -> Iterator[Path]:
    """MuJoCo's ``MUJOCO_LOG.TXT`` (its "simulation is unstable" warnings) in ``folder``.

    MuJoCo appends to that file in the current directory, which Hydra (``chdir=False``)
    leaves at the launch folder: the messages of every run piled up there. MuJoCo 3.3+'s
    ``MjLogConfig`` moves the file without a chdir; the previous setting comes back on exit.
    The setting is per process: forked collector workers inherit it, spawned ones do not.
    """
    import mujoco

    path = Path(folder) / "MUJOCO_LOG.TXT"
    config = mujoco.MjLogConfig.get()
    previous = config.logfile
    config.logfile = str(path)
    config.set()
    try:
        yield path
    finally:
        config.logfile = previous
        config.set()


_DIVERGENCE_WARNED: set[Path] = set()


def warn_diverged(folder: Path, iteration: int, count: float) -> None:
    """Say once per run folder (and process) that simulations diverged, what legoh did and
    where to look: the count per iteration is logged, but a column goes unread."""
    folder = Path(folder).resolve()
    if not count > 0 or folder in _DIVERGENCE_WARNED:
        return
    _DIVERGENCE_WARNED.add(folder)
    warnings.warn(
        f"[legoh] {count:.0f} simulation(s) diverged in iteration {iteration} (|qvel| above "
        f"env.divergence_qvel, or a state MuJoCo reset itself): each was reset and its "
        f"episode truncated. Per iteration: the 'diverged' column of train.csv; MuJoCo's "
        f"messages: {folder / 'MUJOCO_LOG.TXT'}. Many: try a smaller sim.dt, lower PD gains "
        f"or a smaller action scale.", RuntimeWarning, stacklevel=2)
