"""Overlapped collection with a fixed policy lag: ``collector.overlap=true``.

One worker process steps the envs and collects batch k+1 while the learner runs update k,
so the envs and the update share the cores instead of taking turns (bench_train.md). The
batch in flight is always acted with the weights the learner had after update k-1, never
a mix: when the learner takes batch k it sends the worker the request for batch k+1 with
a copy of its weights of that moment, and the worker loads weights only between batches.
So the same seed gives the same run.

Why not torchrl's ``MultiAsyncCollector``: its workers apply weights from a background
thread (or read them from shared memory) whenever they arrive, in the middle of a batch,
so which weights acted a batch depends on timing: two runs of one seed with it diverged at
the fourth iteration (docs/scaling.md). The in-process and multi-worker collectors stay
torchrl's.
"""

from __future__ import annotations

import io
import queue
import signal
import time
import traceback
from collections.abc import Callable, Iterator

import torch
import torch.multiprocessing as mp
from tensordict import TensorDictBase
from torchrl.collectors import Collector
from torchrl.envs import EnvBase

POLL_S = 1.0  # how often a waiting learner checks that the worker is still alive
GRACE_S = 30.0  # a worker stopped mid-batch keeps its sent batch readable this long
STOPPED = (-signal.SIGTERM, 128 + signal.SIGTERM)  # the worker's exit codes after a SIGTERM


class PipelinedCollector:
    """Batches of ``frames_per_batch`` from ``env_factory()``'s envs acted by ``policy``,
    collected in one worker process one batch ahead of the learner.

    Batch 0 is acted with the weights ``policy`` has at construction, batch k+1 with
    those it has when batch k is handed out (the learner's after update k-1, as it starts
    update k). Iterating yields batches until ``total_frames``.
    """

    def __init__(self, env_factory: Callable[[], EnvBase], policy: torch.nn.Module,
                 frames_per_batch: int, total_frames: int, seed: int,
                 env_device: torch.device, policy_device: torch.device) -> None:
        self.policy, self.total_frames = policy, total_frames
        ctx = mp.get_context("spawn")  # a fresh interpreter: no forked MuJoCo/OpenMP threads
        self._weights, self._batches = ctx.Queue(), ctx.Queue()
        # the worker's policy is a copy: passed as a module, torch would move the learner's
        # parameters into shared memory and the worker's weight loads would overwrite them
        copy = io.BytesIO()
        torch.save(policy, copy)
        self._proc = ctx.Process(
            target=_collect, name="legoh-pipelined-collector", daemon=True,
            args=(env_factory, copy.getvalue(), frames_per_batch, seed, env_device,
                  policy_device, torch.get_num_threads(), self._weights, self._batches))
        self._proc.start()
        self._request()  # batch 0

    def _request(self) -> None:
        """Ask for the next batch, acted with a copy of the learner's weights of now."""
        self._weights.put({k: v.detach().to("cpu", copy=True)
                           for k, v in self.policy.state_dict().items()})

    def update_policy_weights_(self) -> None:
        """Nothing to send: the next request carries the weights (torchrl's interface)."""

    def __iter__(self) -> Iterator[TensorDictBase]:
        frames = 0
        while frames < self.total_frames:
            batch = self._next()
            if batch is None:  # the worker was stopped by a signal: no more batches
                return
            frames += batch.numel()
            if frames < self.total_frames:
                self._request()  # collected while the learner updates on this one
            yield batch

    def _next(self) -> TensorDictBase | None:
        """The next batch; None when a SIGTERM stopped the worker (a job scheduler signals
        every process of a job: the learner's own handler then ends the run with a
        checkpoint, ``legoh.runs.GracefulStop``)."""
        while True:
            try:
                kind, item = self._batches.get(timeout=POLL_S)
            except queue.Empty:
                if not self._proc.is_alive():
                    if self._proc.exitcode in STOPPED:
                        print("[legoh] the collector worker was stopped by SIGTERM: no more "
                              "batches", flush=True)
                        return None
                    raise RuntimeError(f"the collector worker died (exit code "
                                       f"{self._proc.exitcode}) before sending a batch") from None
                continue
            if kind == "error":
                raise RuntimeError(f"the collector worker failed:\n{item}")
            return item

    def shutdown(self) -> None:
        """Stop the worker (it may be half-way through a batch no one will read)."""
        if self._proc.is_alive():
            self._weights.put(None)
            self._proc.join(timeout=POLL_S)
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join()
        for q in (self._weights, self._batches):
            q.cancel_join_thread()  # nothing queued is wanted any more
            q.close()


class _Term:
    """SIGTERM in the worker (a job scheduler signals every process of a job): before its
    first batch it leaves at once; after, it leaves once the learner has taken the batch
    it last sent (the learner's next request says so) or ``GRACE_S`` after the signal,
    finishing a batch it is collecting first, since the learner may be reading that batch
    (its tensors travel as file descriptors this process must keep open until they are
    received: leaving earlier failed the learner's read, FileNotFoundError)."""

    def __init__(self) -> None:
        self.busy = self.pending = False
        self.since = 0.0

    def __call__(self, signum: int, frame: object) -> None:
        if not self.busy:
            raise SystemExit(128 + signum)
        self.pending, self.since = True, time.monotonic()

    def request(self, weights: mp.Queue):
        """The learner's next request (its weights; None: stop), or SystemExit once a
        SIGTERM came and the last batch sent was taken or its grace ran out."""
        while True:
            try:
                state = weights.get(timeout=POLL_S)
            except queue.Empty:
                if self.pending and time.monotonic() - self.since > GRACE_S:
                    raise SystemExit(128 + signal.SIGTERM) from None
                continue
            if self.pending:  # the learner took the last batch: nothing left to keep
                raise SystemExit(128 + signal.SIGTERM)
            return state


def _collect(env_factory, policy_bytes: bytes, frames_per_batch: int, seed: int, env_device,
             policy_device, threads: int, weights: mp.Queue, batches: mp.Queue) -> None:
    """The worker: for each request (the learner's weights), one batch; ``None``: stop."""
    # a terminal's Ctrl-C reaches every process of the group: the learner decides when to
    # stop (after its iteration, with a checkpoint) and then stops this worker
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    term = _Term()
    signal.signal(signal.SIGTERM, term)
    try:
        policy = torch.load(io.BytesIO(policy_bytes), weights_only=False)  # our own module
        torch.set_num_threads(threads)
        torch.manual_seed(seed)  # the policy's exploration noise
        collector = Collector(env_factory(), policy, frames_per_batch=frames_per_batch,
                              total_frames=-1, auto_register_policy_transforms=False,
                              env_device=env_device, policy_device=policy_device)
        collector.set_seed(seed)
        stream = iter(collector)
        while (state := term.request(weights)) is not None:
            term.busy = True  # from here a batch is collected or sent, maybe not yet read
            policy.load_state_dict(state)
            batches.put(("batch", next(stream)))
        collector.shutdown()
    except Exception:  # noqa: BLE001 - the learner re-raises it with the traceback
        batches.put(("error", traceback.format_exc()))
