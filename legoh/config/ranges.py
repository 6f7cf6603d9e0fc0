"""Valid ranges of every numeric setting, checked by :func:`legoh.config.validate`.

The schemas fix types, not values: ``env.episode_length_s=-1`` or ``algo.num_envs=0``
would compose and fail minutes later, far from the key. One table of ``(dotted key
pattern, range)`` says what each number may be (patterns use ``fnmatch``: ``*`` matches
within and across dots; the first matching row wins). A two-element list matched by an
:data:`INTERVAL` row is an interval ``[low, high]``: both ends in range and ``low <= high``;
other lists are checked element by element. ``None`` (an unset optional) is not checked.
``tests/test_config.py`` asserts every numeric key of every composed option has a row, so a
new setting needs one.
"""

from __future__ import annotations

import fnmatch
import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from omegaconf import DictConfig, OmegaConf


@dataclass(frozen=True)
class Range:
    """``low <= x <= high`` (``<`` where ``open_low``); None: unbounded on that side."""

    low: float | None = None
    high: float | None = None
    open_low: bool = False
    interval: bool = False  # a [low, high] pair, ordered

    def holds(self, x: float) -> bool:
        """Whether ``x`` lies in the range (NaN never does)."""
        if math.isnan(x):
            return False
        if self.low is not None and (x <= self.low if self.open_low else x < self.low):
            return False
        return self.high is None or x <= self.high

    def __str__(self) -> str:
        lo = "" if self.low is None else f"{self.low:g} {'<' if self.open_low else '<='} "
        hi = "" if self.high is None else f" <= {self.high:g}"
        text = f"{lo}x{hi}" if lo or hi else "any value"
        return f"[low, high] with low <= high, each {text}" if self.interval else text


ANY = Range()
COUNT = Range(1)  # counts and sizes
NON_NEGATIVE = Range(0)  # gains, weights, offsets, margins
POSITIVE = Range(0, open_low=True)  # durations, rates, time steps, lengths
FRACTION = Range(0, 1)
INTERVAL = Range(interval=True)
NON_NEGATIVE_INTERVAL = Range(0, interval=True)
POSITIVE_INTERVAL = Range(0, open_low=True, interval=True)

RANGES: list[tuple[str, Range]] = [
    # top level
    ("seed", NON_NEGATIVE), ("stand_seconds", POSITIVE),
    ("web.port", Range(0, 65535)),  # 0: any free port
    ("play.robots", COUNT),
    ("sim.dt", POSITIVE), ("sim.decimation", COUNT), ("sim.threads", NON_NEGATIVE),
    ("sim.hfield_chunk", POSITIVE), ("sim.nconmax", COUNT), ("sim.njmax", COUNT),
    ("sim.overflow_check_every", NON_NEGATIVE),
    # robot: gains and limits from the MJCF side; the pose and Table 6 weights are signed
    ("robot.kp.*", NON_NEGATIVE), ("robot.kd.*", NON_NEGATIVE),
    ("robot.torque_limit.*", POSITIVE), ("robot.default_pose.*", ANY),
    ("robot.table6_weights.*", ANY), ("robot.reward_scales.*", NON_NEGATIVE),
    ("robot.camera.pos", ANY),
    ("robot.camera.pitch_deg", Range(-90, 90)), ("robot.camera.fovy_deg", Range(0, 180, True)),
    ("robot.action_scale", POSITIVE), ("robot.effort_action_scale", POSITIVE),
    ("robot.nominal_base_height", POSITIVE),
    # trail
    ("trail.levels", COUNT), ("trail.variants", COUNT),
    ("trail.segment_length", POSITIVE_INTERVAL),
    ("trail.clearance", NON_NEGATIVE), ("trail.border", NON_NEGATIVE),
    ("trail.start_pad", NON_NEGATIVE), ("trail.max_elevation", NON_NEGATIVE),
    ("trail.detour_noise", NON_NEGATIVE), ("trail.hill_rise", NON_NEGATIVE),
    ("trail.*", POSITIVE),  # tile sizes, resolutions, spacing, edge grade
    # algo (oracle, unified and the baselines)
    ("algo.gamma", FRACTION), ("algo.gae_lambda", FRACTION),
    ("algo.weights.c_*", FRACTION), ("algo.weights.*", NON_NEGATIVE),
    ("algo.desired_kl", NON_NEGATIVE), ("algo.entropy_coef", NON_NEGATIVE),
    ("algo.value_coef", NON_NEGATIVE), ("algo.hlm_margin", NON_NEGATIVE),
    ("algo.pn_*", ANY),  # reward weights: signed like env.rewards
    ("algo.lr", POSITIVE), ("algo.adaptation_lr", POSITIVE), ("algo.vae_lr", POSITIVE),
    ("algo.clip_epsilon", POSITIVE), ("algo.init_noise_std", POSITIVE),
    ("algo.tanh_bound", POSITIVE), ("algo.label_clip", POSITIVE), ("algo.max_grad_norm", POSITIVE),
    ("algo.depth_far", POSITIVE),
    ("algo.distill_share", Range(0, 1, open_low=True)),
    ("algo.prior_pretrain_*", NON_NEGATIVE),  # 0: no pre-training of the prior
    ("algo.dagger_mix_iterations", NON_NEGATIVE),  # 0: the student always acts
    ("algo.distill_warmup_iterations", NON_NEGATIVE),  # 0: the imitation lr from the start
    ("algo.*", COUNT),  # num_envs, steps, frames, epochs, minibatches, every-N, threads
    # eval
    ("eval.seconds", POSITIVE), ("eval.levels", NON_NEGATIVE), ("eval.seed", NON_NEGATIVE),
    ("eval.spawn_remaining", NON_NEGATIVE_INTERVAL), ("eval.tc_radius", POSITIVE),
    ("eval.reach_radius", POSITIVE),
    ("eval.*", COUNT),
    # collector
    ("collector.workers", COUNT), ("collector.init.num_cpus", COUNT),
    ("collector.cpus_per_worker", NON_NEGATIVE), ("collector.gpus_per_worker", NON_NEGATIVE),
    ("collector.memory_per_worker", POSITIVE),
    # env
    ("env.rewards.*", ANY),
    ("env.history", COUNT), ("env.depth.every", COUNT),
    ("env.depth.history", COUNT), ("env.depth.stride", COUNT),
    ("env.depth.width", COUNT), ("env.depth.height", COUNT),
    ("env.randomization.pool_size", COUNT),
    ("env.min_base_height", FRACTION), ("env.command.zero_prob", FRACTION),
    ("env.gait.stance", FRACTION), ("env.gait.yield_pay", FRACTION),
    ("env.command.speed", NON_NEGATIVE_INTERVAL), ("env.randomization.friction",
                                                   NON_NEGATIVE_INTERVAL),
    ("env.randomization.base_mass_offset", INTERVAL),
    ("env.randomization.motor_strength", NON_NEGATIVE_INTERVAL),
    ("env.randomization.gate", FRACTION), ("env.randomization.gate_window", COUNT),
    ("env.randomization.ramp_steps", COUNT),
    ("env.randomization.push_interval_s", POSITIVE),  # 0 would push at every step
    ("env.randomization.*", NON_NEGATIVE),  # offsets, speeds, delays, step counts
    ("env.curriculum.lagging_mix", FRACTION),
    ("env.curriculum.*", NON_NEGATIVE),
    ("env.spawn_noise", NON_NEGATIVE), ("env.spawn_remaining", NON_NEGATIVE_INTERVAL),
    ("env.spawn_along", FRACTION),
    ("env.air_time_target", NON_NEGATIVE),
    ("env.edge_min_level", NON_NEGATIVE),
    ("env.command.*", NON_NEGATIVE), ("env.gait.swing_height", NON_NEGATIVE),
    ("env.gait.yield_near", NON_NEGATIVE),  # 0: the gait clock everywhere
    ("env.*", POSITIVE),  # durations, radii, angles, clips, speeds, sigmas
]
# pairs of keys that must be ordered (first <= second) when both are set
ORDERED = [("env.curriculum.down", "env.curriculum.up")]


def numeric_leaves(node: Any, path: str = "") -> Iterator[tuple[str, Any]]:
    """``(dotted key, value)`` of every number, or list holding numbers, under ``node``."""
    if isinstance(node, dict):
        for key, value in node.items():
            yield from numeric_leaves(value, f"{path}.{key}".lstrip("."))
    elif isinstance(node, list):
        if any(_is_number(v) for v in node):
            yield path, node
    elif _is_number(node):
        yield path, node


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def rule_for(key: str) -> Range | None:
    """The first :data:`RANGES` row whose pattern matches ``key``; None when none does."""
    return next((r for pattern, r in RANGES if fnmatch.fnmatchcase(key, pattern)), None)


def check_ranges(cfg: DictConfig) -> None:
    """Refuse the first numeric setting outside its range, naming key, value and range."""
    plain = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)
    values = dict(numeric_leaves(plain))
    for key, value in values.items():
        rule = rule_for(key)
        if rule is None:
            continue
        items = value if isinstance(value, list) else [value]
        bad = [v for v in items if _is_number(v) and not rule.holds(float(v))]
        unordered = rule.interval and (len(items) != 2 or items[0] > items[1])
        if bad or unordered:
            raise ValueError(f"{key}={value} is out of range: {key} must be {rule}")
    for low, high in ORDERED:
        if _is_number(values.get(low)) and _is_number(values.get(high)) \
                and values[low] > values[high]:
            raise ValueError(f"{low}={values[low]} must not exceed {high}={values[high]}")
