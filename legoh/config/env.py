"""HikingEnv config schema (the ``env`` node of ``conf/config.yaml``)."""

from dataclasses import dataclass, field, replace
from enum import Enum, StrEnum


def table6_weights() -> dict[str, float]:
    """Reward weights of appendix Table 6, the ``table6`` preset (the robot-specific column
    comes from robot.table6_weights).

    ``pn_distance`` (point-navigation distance) is used by the unified stage only: 0 here,
    as are that stage's progress form (``pn_progress``, ``pn_line_progress``, ``pn_reach``;
    ``algo.nav_reward``, docs/unified.md).
    """
    return {
        "tracking_goal_vel": 10.0,
        "tracking_yaw": 0.5,
        "lin_vel_z": -2.0,
        "ang_vel_xy": -1.0,
        "orientation": -1.0,
        "dof_acc": -3.5e-8,
        "collision": -10.0,
        "action_rate": -0.01,
        "delta_torques": -1.0e-7,
        "torques": -1.0e-5,
        "hip_pos": -0.5,
        "dof_error": -0.04,
        "feet_stumble": -1.0,
        "feet_edge": -1.0,
        "feet_air_time": 1.0,
        "base_height": -100.0,
        "pn_distance": 0.0,
        "pn_progress": 0.0,
        "pn_line_progress": 0.0,
        "pn_reach": 0.0,
        "dof_pos_limits": 0.0,
        # legged_gym's termination term (Cassie: -200), per fall x dt, paid after the clip:
        # without the clip and this term our first 2M-frame study learned to dive at the goal
        "termination": -200.0,
    }


def walk_weights() -> dict[str, float]:
    """The ``walk`` preset (learn_walk's): unitree_rl_gym's H1 walking recipe on our terms
    (exp-kernel velocity tracking, alive bonus, contact phase of a gait clock, swing height).
    Where each term departs from Table 6 and the curves that chose it: docs/oracle.md."""
    return {
        "tracking_lin_vel": 1.0,
        # the same kernel toward the next waypoint (0 here: learn_walk's walkers were trained
        # without it; the hiking recipe swaps tracking_lin_vel for it, docs/oracle.md)
        "tracking_waypoint_vel": 0.0,
        "tracking_ang_vel": 0.5,
        "alive": 0.15,
        "lin_vel_z": -2.0,
        "ang_vel_xy": -0.05,
        "orientation": -1.0,
        "base_height": -10.0,
        "dof_acc": -2.5e-7,
        "dof_vel": -1.0e-3,
        "action_rate": -0.01,
        "dof_pos_limits": -5.0,
        "hip_pos": -1.0,
        "feet_contact_phase": 0.18,
        "feet_swing_height": -20.0,
        "feet_phase": 1.0,
        "pn_distance": 0.0,  # the unified stage's navigation terms (algo.nav_reward)
        "pn_progress": 0.0,
        "pn_line_progress": 0.0,
        "pn_reach": 0.0,
        # unitree_rl_gym has no termination term: a fall forfeits the rest of the episode's
        # reward (-4 per fall kept our first walk attempt standing)
        "termination": 0.0,
    }


def hike_weights() -> dict[str, float]:
    """The ``hike`` preset (the default): the walk preset with its velocity kernel toward the
    next expert waypoint instead of along the robot's heading. The heading form paid a
    circle in full, and session 1 of the hiking campaign learned to walk in circles with it
    (docs/oracle.md); the shipped oracles were trained with this one."""
    return {**walk_weights(), "tracking_lin_vel": 0.0, "tracking_waypoint_vel": 1.0}


def leap_weights() -> dict[str, float]:
    """The ``leap`` preset (the default since 2026-12-05; ``hike`` keeps the shipped oracles'
    recipe): ``hike`` plus what pays for crossing gaps and hurdles. Table 6's clearance terms
    at the hike preset's scale (a tenth of Table 6's: its velocity kernel weighs 1 where
    Table 6's goal velocity weighs 10): collision -1 (any non-foot body on the terrain),
    feet_stumble -0.1, feet_edge -0.1 (from level 1, ``env.edge_min_level``); and Table 6's
    feet_air_time +1 (H1's column), which pays a long step at touch-down, only where the
    gait clock yields (``leap_air_time``): near edges, pits and obstacles
    (``env.gait.yield_near``). Heights are the support's (``env.height_reference``). Why
    each: docs/oracle.md."""
    return {**hike_weights(), "collision": -1.0, "feet_stumble": -0.1, "feet_edge": -0.1,
            "leap_air_time": 1.0}


# name -> (weights, clip the step's total at 0)
REWARD_PRESETS = {
    # legged_gym's defaults around Table 6 (Extreme Parkour trains with them), with its
    # termination term (in the weights) added after the clip
    "table6": (table6_weights, True),
    # every step of a standing robot earns (alive, the kernels), so nothing is clipped
    "walk": (walk_weights, False),
    "hike": (hike_weights, False),
    "leap": (leap_weights, False),
}


class DepthBackend(Enum):
    """How depth frames are made (``env.depth.backend``; docs/env.md, "Depth backends")."""

    raymarch = "raymarch"  # torch ray-march of the terrain map, on the env's device
    multiray = "multiray"  # MuJoCo's ray cast: mj_multiRay (CPU), mjw.rays (sim.backend=warp)


def depth_backend(value: DepthBackend | str) -> DepthBackend:
    """``value`` as a DepthBackend; a ValueError naming the key, the value and the choices
    for anything else (a config from Python, not Hydra, is not checked at composition)."""
    try:
        return DepthBackend(value)
    except ValueError:
        raise ValueError(f"env.depth.backend={value!r} is not a depth backend; valid choices: "
                         f"{[b.value for b in DepthBackend]}") from None


def depth_window(cfg) -> list[int]:
    """Indices into the last ``cfg.history`` frames (oldest first, newest last) of the frames
    a student sees: the newest and every ``cfg.stride``-th before it, oldest first."""
    newest = cfg.history - 1
    return list(range(newest, -1, -cfg.stride))[::-1]


@dataclass
class DepthConfig:
    """Egocentric depth input: the one home of the image's size and far plane (the camera's
    pose and field of view: robot.camera)."""

    enabled: bool = False  # stages that need no depth do not pay for it
    # raymarch: multiray's images but for ~1 % of the pixels on stepping stones, 5-18x
    # cheaper a frame; multiray: MuJoCo's exact ray cast, the reference (docs/env.md)
    backend: DepthBackend = DepthBackend.raymarch
    every: int = 5  # policy steps between frames (10 Hz at 50 Hz)
    # the frames a student sees: of the last ``history`` frames, every ``stride``-th counting
    # back from the newest (depth_window). The paper's 16 sub-sampled to 4: 0, 0.5, 1.0 and
    # 1.5 s old at 10 Hz
    history: int = 16
    stride: int = 5
    width: int = 32  # pixels: the cost of depth grows with pixels (experiments/bench.py env)
    height: int = 24  # pixels
    far: float = 3.0  # m: range clip; frames are depth / far - 0.5


class WaypointPass(StrEnum):
    """When an expert waypoint counts as passed (``env.waypoint_pass``)."""

    radius = "radius"  # within env.waypoint_radius of it (the oracle's, Extreme Parkour's)
    # also once past it along the path: beyond the line through it square to the segment
    # that leads to it. A robot passing beside one is not labelled back toward it
    past = "past"


class HeightReference(StrEnum):
    """What base and foot heights are measured against (``env.height_reference``)."""

    # the height field straight below: pit floors included, so a foot over a gap reads ~1 m
    # of lift and a base over it ~1 m too high (the shipped oracles trained with it)
    ground = "ground"
    # the surface the robot stands on: the scan heights (box tops included) with pits up to
    # ``env.support_window`` wide filled to their rim (a grey closing; docs/env.md)
    support = "support"


class LevelRule(StrEnum):
    """How a finished training episode sets its robot's next level (``env.curriculum.rule``)."""

    # appendix 6.2.1: up past ``up`` of the expected distance, down below ``down``, random
    # after the top (the oracle's: RL learns where it starts to fail)
    distance = "distance"
    # a uniform draw over every level, whatever the episode did: a DAgger student, whose
    # labels are good on any level, trains on the benchmark's own mix of levels instead of
    # the low ones its falls keep it on (docs/unified.md)
    uniform = "uniform"


class Schedule(StrEnum):
    """When randomisation comes in (``env.randomization.schedule``)."""

    gate = "gate"  # by performance: a ramp that advances while training robots stay up
    steps = "steps"  # by step counts (Extreme Parkour's, appendix Table 5's "24 x 8000")


@dataclass
class RandomizationConfig:
    """Appendix Table 5. Per-env physics parameters come from a pool of model copies.

    Everything here comes in through one strength s in [0, 1] that the env owns: a reset
    env steps a randomised pool member with probability s (else the nominal model), gets
    an action delay with probability s, and pushes kick up to s x ``push_max_vel``.
    ``schedule=gate`` (default) raises s by ``1 / ramp_steps`` per vectorised step while the
    share of training episodes ended in about the last ``gate_window`` steps that were not
    falls is at least ``gate``; it never goes down. ``schedule=steps`` is the step-count
    switch of Extreme Parkour (s jumps to 1 at ``start_after_steps``; delays from
    ``delay_after_steps``), which collapsed a walker's episodes from 20 s to 4 s (docs/oracle.md).
    """

    enabled: bool = True
    pool_size: int = 8  # model copies with their own friction, mass, CoM, motor strength
    friction: list[float] = field(default_factory=lambda: [0.6, 2.0])
    base_mass_offset: list[float] = field(default_factory=lambda: [0.0, 3.0])  # kg
    base_com_offset: float = 0.2  # m: base CoM shifted by U(-x, x) per axis
    motor_strength: list[float] = field(default_factory=lambda: [0.8, 1.2])
    push_interval_s: float = 8.0  # s
    push_max_vel: float = 0.5  # m/s, xy
    max_action_delay: int = 1  # policy steps of delay
    # false: the privileged input shows every robot the nominal draw while the draws still
    # act, to measure how much an oracle leans on knowing them (randomization_gap.py --blind)
    observe_physics: bool = True
    schedule: Schedule = Schedule.gate
    # share of recently ended episodes not falls that lets the ramp advance. The curriculum
    # keeps robots where they start to fail: at 0.8 the gate never opened in the first hiking
    # run (survival 0.4-0.6 from level 0.1 on); at 0.5 it ramps while most robots stay up
    gate: float = 0.5
    gate_window: int = 1000  # vectorised steps the gate looks back (one 20 s episode)
    ramp_steps: int = 12_000  # vectorised steps from s = 0 to 1 with the gate open (500 x 24)
    # schedule=steps: the schedule counts vectorised steps (one per env.step of the whole
    # batch, legged_gym's common_step_counter). Extreme Parkour: delays after 24 x 8000.
    start_after_steps: int = 24_000  # 1000 iterations of 24 steps
    delay_after_steps: int = 36_000  # 1500 iterations of 24 steps


def from_first_step(rand: RandomizationConfig, enabled: bool | None = None
                    ) -> RandomizationConfig:
    """``rand`` at full strength from the first step (physics draws, pushes and action
    delays; the step-count schedule switched on at step 0): for a trained policy (the
    benchmark, walk tests) and for stage 2 (its teacher trained under it)."""
    return replace(rand, enabled=rand.enabled if enabled is None else enabled,
                   schedule=Schedule.steps, start_after_steps=0, delay_after_steps=0)


@dataclass
class CommandConfig:
    """The velocity command the walking rewards track: forward speed drawn per episode,
    yaw rate steering toward the next expert waypoint (legged_gym's heading command).
    Evaluation commands ``env.goal_speed`` and never zero."""

    # m/s, uniform per episode: up to 1.5 as Extreme Parkour samples, room for the long
    # steps of gaps (the shipped oracles trained with [0.3, 1.0])
    speed: list[float] = field(default_factory=lambda: [0.3, 1.5])
    zero_prob: float = 0.1  # fraction of training episodes told to stand still (a skill too)
    heading_gain: float = 1.0  # rad/s of yaw rate per rad of heading error
    max_yaw_rate: float = 1.0  # rad/s


@dataclass
class GaitConfig:
    """A gait clock (unitree_rl_gym's H1): legs half a period apart, each in stance for the
    first ``stance`` of its cycle; its phase (sin, cos) is observed. A standing command asks
    both feet to stay down."""

    period: float = 0.8  # s
    stance: float = 0.55  # fraction of the cycle in stance
    swing_height: float = 0.08  # m, foot lift the swing-height term asks for
    phase_sigma: float = 0.005  # m^2, the feet-phase term's exp(-err^2 / sigma)
    # the clock yields to the terrain: its terms (feet_phase, feet_contact_phase,
    # feet_swing_height) weigh 0 within ``yield_near`` m of an edge, pit or obstacle and
    # fade back to 1 over the next ``yield_fade`` m, so steps there may be long and high.
    # 0: the clock everywhere (the shipped oracles' recipe)
    yield_near: float = 0.6  # m
    yield_fade: float = 0.6  # m
    # what the clock's positive terms pay where it yields, as a share of their best: at 0
    # the zone was a tax (they are half a walker's positive reward, and Gap trails lie 90 %
    # in the zone); 0.6 is what the H1 v2 campaign's walkers earned of them on RandomMix, so
    # a step near an obstacle pays as one elsewhere (docs/oracle.md, "Recipe v2")
    yield_pay: float = 0.6


@dataclass
class CurriculumConfig:
    """Appendix 6.2.1 (corrected): up above ``up``, down below ``down`` of the expected distance."""

    enabled: bool = True
    rule: LevelRule = LevelRule.distance
    up: float = 0.8
    down: float = 0.4
    start_level: int = 0  # max initial level (uniform in 0..start_level)
    # share of ended episodes whose next category is drawn with weight (levels - the
    # category's mean level), so robots flow to the categories that lag (issue 44); 0: each
    # robot keeps one category (robot index % categories, the shipped oracles' split)
    lagging_mix: float = 0.5


@dataclass
class EnvConfig:
    """HikingEnv: observations, rewards, terminations (the batch size is the caller's:
    ``make_env(cfg, num_envs)``)."""

    episode_length_s: float = 20.0  # s (training; evaluation sets 30)
    # training: each robot's first episode times out after a uniform random share of
    # episode_length_s, so time-outs (and resets) spread over the episode instead of coming
    # all at once (rsl_rl's init_at_random_ep_len). Without it every start and resume began
    # with ~40 iterations in which only falls could end an episode (logged falls 0.36 ->
    # 0.7 at each resume of the H1 campaign). Evaluation envs never stagger
    stagger_timeouts: bool = True
    # actions are clipped to [-clip, clip] before scaling. 20 units of the per-joint scale
    # (robot.effort_action_scale x torque limit / kp) let a hip reach 1.25 rad, an ankle 0.25
    action_clip: float = 20.0
    goal_speed: float = 0.8  # m/s, the speed the goal-velocity reward asks for
    waypoint_radius: float = 0.6  # m: an expert waypoint counts as passed within this
    # radius: passed only within waypoint_radius; past: also once beyond it along the path
    # (stage 2 trains with past, docs/unified.md; evaluations use radius)
    waypoint_pass: WaypointPass = WaypointPass.radius
    reach_radius: float = 0.5  # m: terminus reached in training (evaluation: eval.reach_radius)
    # a reach truncates the episode (bootstrapped: reaching costs no future reward, as Extreme
    # Parkour's last goal); false: it terminates (recipe v1; with positive steps the robot
    # learns to stop short of the terminus: docs/oracle.md, "Recipe v2")
    reach_truncates: bool = True
    max_roll: float = 0.8  # rad, pose check
    max_pitch: float = 1.0  # rad, pose check
    min_base_height: float = 0.5  # fraction of the nominal base height above the ground
    history: int = 10  # proprioception history length
    spawn_noise: float = 0.3  # m, xy jitter of the spawn point
    # m of expert path left to the terminus, [lo, hi]: each reset puts the robot on an
    # expert waypoint whose remaining path lies in it (the one closest to it when none
    # does; never the terminus), facing the next one. None: at the trail start (training).
    # The curriculum's covered distance still counts from the trail start.
    spawn_remaining: list[float] | None = None
    # training (spawn_remaining None): this share of robots spawns along the trail instead
    # of at its start, on support with the category's obstacle ahead (mdp.spawns), so
    # training sees the far half of a trail; the curriculum counts from the spawn point
    spawn_along: float = 0.5
    divergence_qvel: float = 1.0e3  # |qvel| above this counts as a diverged simulation
    # base and foot heights (base_height, feet_swing_height, feet_phase, the low-base
    # termination) against the ground straight below or the support (HeightReference)
    height_reference: HeightReference = HeightReference.support
    support_window: float = 1.0  # m: pits up to this wide count as filled to their rim
    # torch.compile what a step derives from the physics (state, terminations, rewards,
    # the state's observation terms) into one graph per env: about half the milliseconds
    # outside the physics, 4-15 s of compiling at the first step and first reset (a C++
    # compiler on the CPU; docs/env.md, experiments/bench.py env). None (auto): on the CPU
    # from COMPILE_MIN_ENVS robots up where a C++ compiler works; true: always; false: never
    compile: bool | None = None
    # reward preset (REWARD_PRESETS): leap (default: hike + clearance and air-time terms) |
    # hike (the shipped oracles') | walk (learn_walk's flat-ground recipe: velocity along the
    # heading) | table6 (appendix Table 6 as written)
    reward_preset: str = "leap"
    # weight per term over the preset's; None keeps the preset's (a term of your own:
    # +env.rewards.my_term=1.0 after registering it with legoh.envs.mdp.rewards.reward_term)
    rewards: dict[str, float | None] = field(default_factory=lambda: dict.fromkeys(
        sorted(set(table6_weights()) | set(walk_weights()) | set(leap_weights()))))
    # None: the preset's. True clips the step's total at 0 (legged_gym's only_positive_rewards)
    only_positive_rewards: bool | None = None
    tracking_sigma: float = 0.25  # m^2/s^2, the velocity kernels' exp(-err^2 / sigma)
    air_time_target: float = 0.5  # s, Table 6 feet air time
    # the feet-edge term counts on levels above this one: 0, from level 1 (Extreme Parkour's
    # 3 is of its 10 levels; ours were 3 of 5 until 2026-12-05, i.e. level 4 alone)
    edge_min_level: int = 0
    command: CommandConfig = field(default_factory=CommandConfig)
    gait: GaitConfig = field(default_factory=GaitConfig)
    depth: DepthConfig = field(default_factory=DepthConfig)
    randomization: RandomizationConfig = field(default_factory=RandomizationConfig)
    curriculum: CurriculumConfig = field(default_factory=CurriculumConfig)
