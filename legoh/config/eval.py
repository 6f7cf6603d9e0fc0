"""Benchmark protocol schema (``conf/eval/*.yaml``): how many robots, how long, which scenes."""

from dataclasses import dataclass, field


@dataclass
class EvalConfig:
    """One evaluation protocol (appendix Table 8: 256 robots, 30 s, 5 levels x 5 variants,
    5 runs). Each run builds its own terrain and env from seed ``seed + run``."""

    robots: int = 256  # robots per run (spread round-robin over the categories)
    seconds: float = 30.0  # s, episode length (a robot's first episode counts)
    categories: list[str] = field(default_factory=list)  # trail categories; empty: the trail's
    levels: list[int] = field(default_factory=lambda: [0, 1, 2, 3, 4])  # levels evaluated
    variants: int = 5  # random variants per (category, level) in the evaluation map
    runs: int = 5  # repetitions, each with its own seed; tables give mean ± std over runs
    # run r uses seed + r for the terrain and the env; None follows the run's top-level
    # ``seed`` (one seed rules unless this is set)
    seed: int | None = None
    # m of expert path left from each robot's spawn waypoint to the terminus, [lo, hi]
    # (env.spawn_remaining): at the 0.8 m/s evaluation command a flawless walk of 2-10 m
    # takes 2.5-12.5 s, mean 7.5 s, inside Table 8's T2R of 4.2-13.7 s; from the trail start
    # (22 m) it would take 27.5 of the 30 s. None: every robot at the trail start
    spawn_remaining: list[float] | None = field(default_factory=lambda: [2.0, 10.0])
    tc_radius: float = 0.3  # m: TC counts a waypoint the torso passed within this
    reach_radius: float = 0.89  # m: the terminus counts as reached within this (env.reach_radius)
    # Table 5's randomisation (physics draws, pushes, action delay) on from the first step
    randomization: bool = True
