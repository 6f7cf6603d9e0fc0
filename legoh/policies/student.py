"""The depth students (LEGO-H's unified policy and the baselines) and the env they act in:
the same ``HikingEnv`` with depth on, wrapped with torchrl's ``InitTracker`` and a primer
for the navigation module's recurrent state."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch
from omegaconf import DictConfig, OmegaConf
from torchrl.data import Composite, Unbounded
from torchrl.envs import Compose, EnvBase, InitTracker, TensorDictPrimer, TransformedEnv

from legoh import keys
from legoh.checkpoint import CheckpointError, load_checkpoint
from legoh.config.algo import NavReward, StageRandomization
from legoh.config.env import CommandConfig, WaypointPass, from_first_step
from legoh.envs.hiking_env import make_env
from legoh.modules.students import Student, StudentDims, make_student

PROBE_SHAPES = ((1,), 1)  # any recurrent state shape: a probe env only sizes the student


def nav_reward_weights(algo) -> dict[str, float]:
    """The weights of this stage's navigation terms (``algo.nav_reward``), over
    ``env.rewards``: the progress form (progress toward the terminus + the reach bonus)
    or the paper's point-navigation distance. The other forms' terms get 0."""
    form = NavReward(str(getattr(algo.nav_reward, "value", algo.nav_reward)))
    weights = dict.fromkeys(("pn_distance", "pn_progress", "pn_line_progress", "pn_reach"), 0.0)
    if form == NavReward.paper:
        weights["pn_distance"] = float(algo.pn_distance)
    else:
        term = "pn_progress" if form == NavReward.progress else "pn_line_progress"
        weights[term] = float(algo.pn_progress)
        weights["pn_reach"] = float(algo.pn_reach)
    return weights


def student_command(cfg: DictConfig) -> CommandConfig:
    """The forward-speed command of stage 2: the evaluation's, ``env.goal_speed`` for every
    episode, never zero. The oracle reads the command and the student cannot see it, so a
    drawn one would make the labels depend on an input the student has no way to infer."""
    command = OmegaConf.to_object(cfg.env.command)  # a CommandConfig
    speed = float(cfg.env.goal_speed)
    return dataclasses.replace(command, speed=[speed, speed], zero_prob=0.0)


def student_env_overrides(cfg: DictConfig, evaluation: bool = False) -> dict:
    """Env settings of stage 2: depth on (unless the student is blind), the stage's
    navigation reward (:func:`nav_reward_weights`), the student's depth range, the
    evaluation's speed command (:func:`student_command`); in training, waypoints pass
    once the robot is past them (``env.waypoint_pass=past``: the oracle's labels do not
    turn a robot back to a waypoint it walked by) and, with ``algo.randomization=full``,
    Table 5's randomisation at full strength from the first step. Evaluations keep
    ``env.waypoint_pass`` (radius), so a student's TR and TC count as its oracle's do, and
    the benchmark's own randomisation."""
    depth = OmegaConf.to_object(cfg.env.depth)  # a DepthConfig
    depth.enabled = cfg.algo.student != "rma_b"
    if cfg.algo.depth_far is not None:
        depth.far = float(cfg.algo.depth_far)
    rewards = {**dict(cfg.env.rewards), **nav_reward_weights(cfg.algo)}
    out = {"depth": depth, "rewards": rewards, "command": student_command(cfg)}
    if not evaluation:
        out["waypoint_pass"] = WaypointPass.past
        mode = StageRandomization(str(getattr(cfg.algo.randomization, "value",
                                              cfg.algo.randomization)))
        rand = OmegaConf.to_object(cfg.env.randomization)  # a RandomizationConfig
        if mode == StageRandomization.full and rand.enabled:
            out["randomization"] = from_first_step(rand)
    return out


def wrap_student_env(env: EnvBase, state_spec) -> TransformedEnv:
    """InitTracker (``is_init``) + zeros for the navigation module's recurrent state."""
    return TransformedEnv(env, Compose(InitTracker(),
                                       TensorDictPrimer(state_spec, expand_specs=False)))


def make_student_env(cfg: DictConfig, num_envs: int, state_shapes: tuple, evaluation=False,
                     **overrides) -> TransformedEnv:
    """A stage-2 env (picklable through functools.partial: collector workers build it).
    ``state_shapes``: :func:`state_shapes` of the student that acts in it."""
    state_shape, held_dim = state_shapes
    env = make_env(cfg, num_envs=num_envs, evaluation=evaluation,
                   **{**student_env_overrides(cfg, evaluation), **overrides})
    spec = Composite({keys.NAV_STATE: Unbounded(shape=(num_envs, *state_shape)),
                      keys.NAV_HELD: Unbounded(shape=(num_envs, held_dim))},
                     shape=(num_envs,))
    return wrap_student_env(env, spec)


def state_shapes(student: Student) -> tuple:
    """(core state shape, held size) of a student's navigation: what its env must prime."""
    nav = student.navigation.navigator
    return tuple(nav.state_shape), int(nav.held_dim)


def build_student(cfg: DictConfig, env: EnvBase | None = None) -> Student:
    """The student of ``cfg.algo`` sized from a stage-2 env's specs (None: a one-robot
    probe env, built and closed here)."""
    if env is None:
        probe = make_student_env(cfg, 1, PROBE_SHAPES)
        try:
            return build_student(cfg, probe)
        finally:
            probe.close()
    algo = cfg.algo
    far = algo.depth_far if algo.depth_far is not None else cfg.env.depth.far
    dims = StudentDims.from_spec(env.observation_spec, depth_far=float(far))
    # every student acts with the same fixed noise (docs/unified.md, "The same exploration")
    return make_student(algo.student, dims, env.action_spec.shape[-1], algo.tanh_bound,
                        preset=algo.net, core=algo.core, init_std=algo.init_noise_std,
                        learn_std=False, history_latent=bool(algo.history_latent))


# what a depth student's frames depend on beyond their shape (the layout checks that): a
# student that learned from one camera pose or depth range sees nonsense through another.
# And what it reads beyond them: algo.history_latent (absent from older checkpoints: off)
SENSOR_KEYS = ("robot.camera.body", "robot.camera.pos", "robot.camera.pitch_deg",
               "robot.camera.fovy_deg", "env.depth.far", "env.depth.every",
               "env.depth.history", "env.depth.stride", "algo.depth_far",
               "algo.history_latent")
STORED_DEFAULTS = {"algo.history_latent": False}  # what a checkpoint without the key had


def sensor_differences(cfg: DictConfig, stored: dict) -> list[tuple[str, object, object]]:
    """``(key, the checkpoint's value, cfg's value)`` for each ``SENSOR_KEYS`` entry where
    a student's stored config ``stored`` and ``cfg`` differ (keys it did not store, from
    older runs, are skipped); lists compare as plain lists."""
    stored_cfg, absent, out = OmegaConf.create(stored), object(), []
    for key in SENSOR_KEYS:
        have = OmegaConf.select(stored_cfg, key, default=STORED_DEFAULTS.get(key, absent))
        if have is absent:
            continue
        want = OmegaConf.select(cfg, key)
        if OmegaConf.is_config(have):  # a list (the camera's position)
            have, want = list(have), list(want)
        if have != want:
            out.append((key, have, want))
    return out


def check_sensors(cfg: DictConfig, path: str | Path, stored: dict) -> None:
    """Refuse a depth student's checkpoint (its stored config ``stored``) trained with
    another camera or depth setting than ``cfg``'s, naming the key and both values."""
    differences = sensor_differences(cfg, stored)
    if differences:
        key, have, want = differences[0]
        why = ("its locomotion reads the inputs it learned with" if key == "algo.history_latent"
               else "a student sees its depth only through the camera it learned with")
        raise CheckpointError(f"{path} was trained with {key}={have}, but this run has "
                              f"{key}={want}: {why} (pass {key}={have})")


def sensors_from_checkpoint(cfg: DictConfig, path: str | Path) -> DictConfig:
    """``cfg`` with the camera and depth settings (``SENSOR_KEYS``) a student's checkpoint
    was trained with, for using it (evaluation, play, export): a student sees only through
    the camera it learned with, so an old checkpoint stays usable when a default changes.
    Training from a checkpoint (resume) still refuses a mismatch (:func:`check_sensors`).
    Prints the settings it changed."""
    cfg = cfg.copy()
    changed = sensor_differences(cfg, load_checkpoint(path).get("config", {}))
    for key, have, _ in changed:
        OmegaConf.update(cfg, key, have, merge=False)
    if changed:
        print(f"[legoh] {path}: the student's own sensors: "
              + ", ".join(f"{key}={have}" for key, have, _ in changed))
    return cfg


def read_student_checkpoint(cfg: DictConfig, path: str | Path, student: Student) -> dict:
    """A stage-2 checkpoint for ``student``; refuses another robot, layout or student, and
    for a depth student another camera or depth setting (:func:`check_sensors`)."""
    have = load_checkpoint(path, expect_robot=cfg.robot.name)["extra"].get("student")
    if have != cfg.algo.student:  # checked first: the clearest message for a mixed-up path
        raise CheckpointError(f"{path} holds student {have!r}, but this run builds "
                              f"{cfg.algo.student!r} (algo.student)")
    state = load_checkpoint(path, expect_robot=cfg.robot.name,
                            expect_layout=student.dims.as_layout())
    if student.dims.depth is not None:
        check_sensors(cfg, path, state.get("config", {}))
    return state


def load_student(cfg: DictConfig, path: str | Path, student: Student) -> dict:
    """Load a stage-2 checkpoint into ``student`` (:func:`read_student_checkpoint`'s
    checks); returns the checkpoint."""
    state = read_student_checkpoint(cfg, path, student)
    for name, module in student.modules().items():
        module.load_state_dict(state["models"][name])
    return state


def stored_history_latent(path: str | Path) -> bool:
    """Whether a stage-2 checkpoint's student reads a history latent (``algo.history_latent``;
    older checkpoints: no)."""
    stored = OmegaConf.create(load_checkpoint(path).get("config", {}))
    key = "algo.history_latent"
    return bool(OmegaConf.select(stored, key, default=STORED_DEFAULTS[key]))


def load_student_adding_history(cfg: DictConfig, path: str | Path, student: Student,
                                teacher_path: str | Path) -> dict:
    """Warm-start ``student`` (``algo.history_latent=true``) from checkpoint ``path`` of one
    without a history latent: every weight it has is loaded; the locomotion MLP's first
    layer gains zero columns for the latent (so the student first acts exactly as the
    loaded one), and the history encoder starts from the teacher's adaptation module,
    which estimates the same latent (the privileged encoder's) from the same history.
    Returns the checkpoint."""
    plain = cfg.copy()
    OmegaConf.update(plain, "algo.history_latent", False, merge=False)
    state = read_student_checkpoint(plain, path, student)
    nav = student.navigation
    missing, unexpected = nav.load_state_dict(state["models"]["navigation"], strict=False)
    if unexpected or not all(k.startswith("navigator.history.") for k in missing):
        raise CheckpointError(f"{path}: its navigation does not match this student's but for "
                              f"the history encoder (missing {missing}, unexpected {unexpected})")
    adaptation = load_checkpoint(teacher_path)["models"].get("adaptation")
    if adaptation is None:
        raise CheckpointError(f"{teacher_path} holds no adaptation module to start "
                              f"algo.history_latent's encoder from")
    nav.navigator.history.load_state_dict(
        {k.removeprefix("module."): v for k, v in adaptation.items()})
    loco = student.locomotion.state_dict()
    extra = student.navigation.navigator.history_dim
    for key, value in state["models"]["locomotion"].items():
        if loco[key].shape != value.shape:  # the first layer: the latent's columns come last
            if tuple(loco[key].shape) != (value.shape[0], value.shape[1] + extra):
                raise CheckpointError(f"{path}: locomotion weight {key} has shape "
                                      f"{tuple(value.shape)}, this student's "
                                      f"{tuple(loco[key].shape)}")
            value = torch.cat([value, value.new_zeros(value.shape[0], extra)], dim=1)
        loco[key] = value
    student.locomotion.load_state_dict(loco)
    return state


def student_from_checkpoint(cfg: DictConfig, path: str | Path | None) -> Student:
    """The student of ``cfg.algo`` with the weights of ``path`` (None: untrained)."""
    student = build_student(cfg)
    if path:
        load_student(cfg, path, student)
    return student
