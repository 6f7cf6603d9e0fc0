"""Run bookkeeping shared by the training stages: the frame budget left to a resumed run.

Kept apart from the loops (``legoh/train/``) so each rule is one small function a test can
call, and the loops only ask it.
"""

from __future__ import annotations


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
