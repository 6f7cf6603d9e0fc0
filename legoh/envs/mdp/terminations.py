"""Termination terms: ``fn(env, state) -> (N,) bool``, one row of ``TERMINATIONS`` each.

Every row is honoured by the step (:func:`check_terminations`); its ``outcome`` says how the
episode ends when the term fires:

* ``success`` and ``failure`` terminate it (no bootstrapping past it). A failure, unless a
  success fired on the same step, is what the ``termination`` reward term pays and what the
  randomisation gate counts as a fall.
* ``goal`` truncates it (the value past it is bootstrapped) and is reported like a
  success: the task is done, yet reaching it costs the robot no future reward (Extreme
  Parkour ends an episode at its last goal as a time-out; ``env.reach_truncates``).
* ``time_out`` truncates it (the value past it is bootstrapped).

A step whose simulation diverged (the env was reset in place) ends truncated and reports no
outcome. Each term's flag, time-outs excepted, is reported as ``("info", name)``. To add a
term, write the function here and give it a row in ``TERMINATIONS``.
"""

from __future__ import annotations

from collections.abc import Callable
from enum import StrEnum
from typing import NamedTuple

import torch

from legoh.envs.mdp.state import StepState

TerminationFn = Callable[..., torch.Tensor]  # fn(env, state) -> (N,) bool


class Outcome(StrEnum):
    """How an episode ends when a termination term fires."""

    success = "success"  # terminated: the task is done
    failure = "failure"  # terminated: the robot failed (the termination reward term pays)
    goal = "goal"  # truncated: the task is done (reported, never a failure)
    time_out = "time_out"  # truncated


class Termination(NamedTuple):
    """One row of the termination table: the function and the outcome it stands for."""

    fn: TerminationFn
    outcome: Outcome


class Ends(NamedTuple):
    """What the termination table made of one step, each (N,) bool."""

    terminated: torch.Tensor
    truncated: torch.Tensor
    failed: torch.Tensor  # a failure term fired and no success term did
    flags: dict[str, torch.Tensor]  # each term that is not a time-out, by name


def reached(env, s: StepState) -> torch.Tensor:
    """Within the reach radius of the terminus."""
    return torch.linalg.vector_norm(s.terminus_xy - s.base_xy, dim=1) < env.reach_radius


def fell(env, s: StepState) -> torch.Tensor:
    """The pose check: rolled or pitched past its limit, or the base too low."""
    c = env.cfg
    low = s.base_height < c.min_base_height * env.robot.nominal_base_height
    return (torch.abs(s.roll) > c.max_roll) | (torch.abs(s.pitch) > c.max_pitch) | low


def time_out(env, s: StepState) -> torch.Tensor:
    """The episode ran its length (``env.horizon``: ``max_steps``, shorter for a training
    robot's first episode under ``env.stagger_timeouts``)."""
    return env.steps >= env.horizon


TERMINATIONS: dict[str, Termination] = {
    "reached": Termination(reached, Outcome.success),
    "fell": Termination(fell, Outcome.failure),
    "timeout": Termination(time_out, Outcome.time_out),
}


def termination_table(reach_truncates: bool) -> dict[str, Termination]:
    """The env's table: ``TERMINATIONS``, with a reach that truncates (``Outcome.goal``)
    when ``reach_truncates``. A reach that terminates cuts off the value of the steps after
    it: where every step pays more than it costs, a policy learns to stop short of the
    terminus (the H1 v2 campaign's robots stood 1.0-1.4 m from it; docs/oracle.md)."""
    table = dict(TERMINATIONS)
    if reach_truncates and "reached" in table:
        table["reached"] = Termination(table["reached"].fn, Outcome.goal)
    return table


def check_terminations(table: dict[str, Termination], env, s: StepState,
                       diverged: torch.Tensor) -> Ends:
    """Every term of ``table`` on the step's state ``s``; ``diverged`` (N,) bool: envs
    reset in place by this step's divergence check (truncated, no outcome)."""
    flags = {name: term.fn(env, s) & ~diverged for name, term in table.items()}

    def any_of(outcome: Outcome) -> torch.Tensor:
        fired = [flags[name] for name, term in table.items() if term.outcome == outcome]
        return torch.stack(fired).any(0) if fired else torch.zeros_like(diverged)

    success, goal, failure = (any_of(Outcome.success), any_of(Outcome.goal),
                              any_of(Outcome.failure))
    terminated = success | failure
    truncated = (any_of(Outcome.time_out) | goal | diverged) & ~terminated
    reported = {name: flags[name] for name, term in table.items()
                if term.outcome != Outcome.time_out}
    return Ends(terminated, truncated, failure & ~(success | goal), reported)


def no_flags(table: dict[str, Termination], none: torch.Tensor) -> dict[str, torch.Tensor]:
    """The info flags of a step that ended nothing (``none``: (N,) False)."""
    names = [k for k, t in table.items() if t.outcome != Outcome.time_out]
    return {**dict.fromkeys(names, none), "diverged": none}


def diverged_envs(env, time_before: torch.Tensor) -> torch.Tensor:
    """(N,) bool: envs whose state went non-finite or exploded in the last physics step.
    MuJoCo itself resets an MjData whose qpos/qvel/qacc went bad (time restarts at 0, the
    robot jumps to qpos0), so a step that did not advance time counts as diverged too."""
    sim = env.sim
    return (sim.time < time_before + 0.5 * env.dt) | ~torch.isfinite(sim.qpos).all(1) | (
        ~(torch.abs(sim.qvel) <= env.cfg.divergence_qvel).all(1))  # NaN fails the <=
