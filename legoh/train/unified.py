"""Stage 2: a depth student (LEGO-H's unified policy or a baseline) learned from the oracle.

Read it top to bottom: make sure an oracle exists (train one, or reuse the one a previous
run of the same config left in ``artefacts/``), build the student and the depth env, then
per iteration: the student acts (DAgger), the frozen oracle labels the batch (actions and
scandot latent), the action prior (masked VAE for HLM) takes a few steps on the oracle's
actions, PPO updates the locomotion module on the Table 6 + point-navigation rewards, and
the imitation losses (action, latent, goals, HLM) update the whole student through time.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from torchrl.envs import Compose, EnvBase, InitTracker, TensorDictPrimer, TransformedEnv

from legoh import keys
from legoh.checkpoint import CheckpointError, load_checkpoint
from legoh.config.algo import NavReward, OracleConfig
from legoh.config.env import CommandConfig, DepthConfig, WaypointPass
from legoh.envs.hiking_env import make_env
from legoh.modules.actor_critic import LOC, OracleInputDims
from legoh.modules.students import Student, StudentDims, make_student, unroll
from legoh.objectives.distill import distillation_loss
from legoh.objectives.ppo import make_ppo, ppo_update
from legoh.runs import GracefulStop, RunFolderBusy, resume_command, wait_for_run
from legoh.train.dagger import TeacherMix, student_rows, teacher_share
from legoh.train.oracle import (
    build_oracle,
    load_oracle_checkpoint,
    oracle_net_config,
    pretrained_path,
    resolve_checkpoint,
    train_oracle,
)
from legoh.train.prior import make_prior, pretrain_prior, train_prior
from legoh.train.runner import OnPolicyRunner, training_session


@dataclass
class StudentRun:
    """What a stage-2 run leaves behind."""

    student: Student
    checkpoint: Path
    csv: Path
    mcap: Path
    iterations: int
    oracle: Path


# ----------------------------------------------------------------------------- oracle
def oracle_config(cfg: DictConfig) -> DictConfig:
    """The stage-1 config a stage-2 run needs: same robot, trail, env, sim and seed; oracle
    defaults with ``algo.oracle_frames`` as the budget."""
    algo = OmegaConf.structured(OracleConfig(total_frames=int(cfg.algo.oracle_frames)))
    merged = OmegaConf.merge(cfg, {"algo": None})
    merged.algo = algo
    return merged


def oracle_artefact_dir(cfg: DictConfig) -> Path:
    """``artefacts/oracle-<robot>-<trail>-<hash>``: the hash covers every setting that
    changes the oracle, so two stage-2 runs that need the same oracle share it."""
    stage1 = oracle_config(cfg)
    key = OmegaConf.to_yaml(OmegaConf.masked_copy(stage1, ["robot", "trail", "env", "sim",
                                                           "seed", "algo"]), resolve=True)
    digest = hashlib.sha256(key.encode()).hexdigest()[:10]
    return Path(cfg.artefacts) / f"oracle-{cfg.robot.name}-{cfg.trail.name}-{digest}"


def shipped_oracle(robot: str) -> Path | None:
    """``pretrained/<robot>_oracle.pt`` when the repository ships one, else None."""
    try:
        return pretrained_path(robot)
    except FileNotFoundError:
        return None


def ensure_oracle(cfg: DictConfig) -> Path:
    """The oracle checkpoint for this run: ``algo.oracle_checkpoint`` when given
    (``pretrained``: the robot's shipped one); else the robot's shipped oracle when there is
    one; else the artefact of a previous run with the same stage-1 config (resumed if it was
    killed); else one trained now with the small budget ``algo.oracle_frames``."""
    if cfg.algo.oracle_checkpoint:
        return resolve_checkpoint(str(cfg.algo.oracle_checkpoint), cfg.robot.name)
    shipped = shipped_oracle(cfg.robot.name)
    if shipped is not None:
        print(f"[legoh] teacher: the shipped oracle {shipped} (another: "
              f"algo.oracle_checkpoint=PATH)")
        return shipped
    out = oracle_artefact_dir(cfg)
    ckpt, done = out / "oracle.pt", out / "DONE"
    while True:
        wait_for_run(out)  # a job of the same sweep training this oracle: read it after
        if done.is_file() and ckpt.is_file():
            print(f"[legoh] reusing the oracle at {ckpt}")
            return ckpt
        try:
            return _train_artefact_oracle(cfg, out)
        except RunFolderBusy:  # another job took the folder first: wait for it, then read
            continue


def _train_artefact_oracle(cfg: DictConfig, out: Path) -> Path:
    """Train (or resume) the small oracle of ``cfg`` in ``out``, then mark it ``DONE``."""
    ckpt = out / "oracle.pt"
    stage1 = oracle_config(cfg)
    resume = str(ckpt) if ckpt.is_file() else None
    print(f"[legoh] no oracle given: training one ({stage1.algo.total_frames} frames) in {out}")
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.yaml").write_text(OmegaConf.to_yaml(stage1, resolve=True))
    hint = f"{resume_command(None)}   # the same command: it resumes the oracle in {out}"
    run = train_oracle(stage1, out, resume=resume, resume_hint=hint)
    (out / "DONE").write_text(f"{run.iterations} iterations\n")
    return run.checkpoint


def load_oracle(cfg: DictConfig, path: Path, env: EnvBase):
    """The frozen oracle actor and its critic (the student's critic starts from it)."""
    state = load_oracle_checkpoint(path, cfg, OracleInputDims.from_spec(env.observation_spec))
    # the head and critic as that oracle trained them (older checkpoints: the defaults)
    _, actor, critic, _ = build_oracle(env, oracle_net_config(oracle_config(cfg), state))
    actor.load_state_dict(state["models"]["actor"])
    critic.load_state_dict(state["models"]["critic"])
    actor.requires_grad_(False)
    return actor.eval(), critic


# ----------------------------------------------------------------------------- env
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
    turn a robot back to a waypoint it walked by). Evaluations keep ``env.waypoint_pass``
    (radius), so a student's TR and TC count as its oracle's do."""
    depth = OmegaConf.to_object(cfg.env.depth)  # a DepthConfig
    depth.enabled = cfg.algo.student != "rma_b"
    if cfg.algo.depth_far is not None:
        depth.far = float(cfg.algo.depth_far)
    rewards = {**dict(cfg.env.rewards), **nav_reward_weights(cfg.algo)}
    out = {"depth": depth, "rewards": rewards, "command": student_command(cfg)}
    if not evaluation:
        out["waypoint_pass"] = WaypointPass.past
    return out


def wrap_student_env(env: EnvBase, state_spec) -> TransformedEnv:
    """InitTracker (``is_init``) + zeros for the navigation module's recurrent state."""
    return TransformedEnv(env, Compose(InitTracker(),
                                       TensorDictPrimer(state_spec, expand_specs=False)))


def make_student_env(cfg: DictConfig, num_envs: int, state_shapes: tuple, evaluation=False,
                     **overrides) -> TransformedEnv:
    """A stage-2 env (picklable through functools.partial: collector workers build it)."""
    from torchrl.data import Composite, Unbounded

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


def build_student(cfg: DictConfig, env: EnvBase) -> Student:
    """The student of ``cfg.algo`` sized from a stage-2 env's specs."""
    algo = cfg.algo
    far = algo.depth_far if algo.depth_far is not None else cfg.env.depth.far
    dims = StudentDims.from_spec(env.observation_spec, depth_far=float(far))
    # every student acts with the same fixed noise (docs/unified.md, "The same exploration")
    return make_student(algo.student, dims, env.action_spec.shape[-1], algo.tanh_bound,
                        preset=algo.net, core=algo.core, init_std=algo.init_noise_std,
                        learn_std=False)


def load_student(cfg: DictConfig, path: str | Path, student: Student) -> dict:
    """Load a stage-2 checkpoint into ``student``; refuses another robot, layout or student."""
    have = load_checkpoint(path, expect_robot=cfg.robot.name)["extra"].get("student")
    if have != cfg.algo.student:  # checked first: the clearest message for a mixed-up path
        raise CheckpointError(f"{path} holds student {have!r}, but this run builds "
                              f"{cfg.algo.student!r} (algo.student)")
    state = load_checkpoint(path, expect_robot=cfg.robot.name,
                            expect_layout=student.dims.as_layout())
    for name, module in student.modules().items():
        module.load_state_dict(state["models"][name])
    return state


# ----------------------------------------------------------------------------- loop
def label_with_oracle(oracle, batch) -> None:
    """DAgger labels: the oracle's mean action and scandot latent on the student's states."""
    with torch.no_grad():
        out = oracle(batch.select(*oracle.in_keys).clone(recurse=False))
    batch.set(keys.TEACHER_ACTION, out.get(LOC))
    batch.set(keys.TEACHER_LATENT, out.get(keys.TEACHER_LATENT))


def distill(student: Student, batch, cfg: DictConfig, optim, prior_loss,
            gen: torch.Generator) -> dict:
    """``algo.distill_epochs`` passes over the batch in ``algo.minibatches`` groups of envs
    (whole sequences: the recurrent core runs through time); logged values are means."""
    algo = cfg.algo
    n = batch.shape[0]
    groups = max(1, min(algo.minibatches, n))
    sums: dict[str, float] = {}
    for _ in range(algo.distill_epochs):
        for rows in torch.randperm(n, generator=gen).chunk(groups):
            out = distill_step(student, batch[rows.to(batch.device)], cfg, optim, prior_loss)
            for key, value in out.items():
                sums[key] = sums.get(key, 0.0) + value / (algo.distill_epochs * groups)
    return sums


def distill_step(student: Student, batch, cfg: DictConfig, optim, prior_loss) -> dict:
    """One gradient step of the imitation losses over a (n, T) batch, the navigation
    module re-run through time (truncated BPTT over the batch's T steps)."""
    nav_out = unroll(student.navigation, batch)
    head_in = nav_out.clone(recurse=False)
    head_in.set(keys.PROPRIO, batch.get(keys.PROPRIO))
    loc = student.locomotion.module[0](head_in).get(LOC)  # the Gaussian head's mean
    out = distillation_loss(nav_out, loc, batch, cfg.algo.weights, prior_loss)
    total = sum(v for k, v in out.items() if k.startswith("loss_"))
    optim.zero_grad()
    total.backward()
    params = [p for m in student.modules().values() for p in m.parameters()]
    torch.nn.utils.clip_grad_norm_(params, cfg.algo.max_grad_norm)
    optim.step()
    return {f"distill/{k}": float(v.detach()) for k, v in out.items() if v.numel() == 1}


def train_student(cfg: DictConfig, out_dir: Path, resume: str | None = None) -> StudentRun:
    """Train ``cfg.algo.student`` for ``cfg.algo.total_frames`` env steps."""
    with training_session(cfg, out_dir) as stop:
        return _train_student(cfg, out_dir, resume, stop)


def _train_student(cfg: DictConfig, out_dir: Path, resume: str | None,
                   stop: GracefulStop) -> StudentRun:
    algo = cfg.algo
    oracle_path = ensure_oracle(cfg)
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)

    probe = make_student_env(cfg, 1, ((1,), 1))  # sizes only
    student = build_student(cfg, probe)
    probe.close()
    shapes = state_shapes(student)
    env = make_student_env(cfg, algo.num_envs, shapes)
    oracle, critic = load_oracle(cfg, oracle_path, env)
    vae, vae_optim, prior_loss = make_prior(cfg, env.action_spec.shape[-1])
    runner = OnPolicyRunner(cfg, out_dir, env, {**student.modules(), "critic": critic}, {},
                            student.dims.as_layout(), f"{algo.name}.pt",
                            extra={"student": algo.student, "oracle": str(oracle_path)},
                            desc=f"{algo.name} ({algo.student})")
    for module in (*student.modules().values(), oracle, critic, vae):
        if module is not None:
            module.to(runner.device)

    loss, gae = make_ppo(student.locomotion, critic, algo)
    ppo_optim = torch.optim.Adam(loss.parameters(), lr=algo.lr)
    distill_optim = torch.optim.Adam(
        [p for m in student.modules().values() for p in m.parameters()], lr=algo.lr)
    runner.optims.update(ppo=ppo_optim, distill=distill_optim)
    if vae is not None:
        runner.models["vae"], runner.optims["vae"] = vae, vae_optim
    if resume:
        runner.resume(load_student(cfg, resume, student))
        print(f"[legoh] resumed from {resume} at iteration {runner.iteration}")
    elif vae is not None and algo.prior_pretrain_frames > 0:
        rollout_env = make_env(cfg, algo.num_envs, **{**student_env_overrides(cfg),
                                                       "depth": DepthConfig()})  # no frames
        out = pretrain_prior(vae, vae_optim, rollout_env, oracle, cfg, gen)
        rollout_env.close()
        print(f"[legoh] action prior pre-trained on {out['actions']} of the oracle's actions "
              f"({algo.prior_pretrain_steps} steps): reconstruction error "
              f"{out['recon_error_before']:.3f} -> {out['recon_error_after']:.3f} (each "
              f"joint's mean: {out['recon_error_mean_guess']:.3f})")

    policy, mix, done = student.policy, None, [runner.iteration]  # done: updates so far
    if algo.dagger_mix_iterations > 0:
        mix = TeacherMix(student.policy, oracle)
        mix.beta.fill_(teacher_share(runner.iteration, algo.dagger_mix_iterations))
        policy = mix

    def update(batch) -> dict:
        clock = {"labels": time.perf_counter()}
        label_with_oracle(oracle, batch)
        stats = {}
        if vae is not None:
            teacher = batch.get(keys.TEACHER_ACTION)
            stats.update(train_prior(vae, vae_optim, teacher.reshape(-1, teacher.shape[-1]),
                                     cfg, gen))
        clock["prior"] = time.perf_counter()
        if algo.ppo and algo.weights.w1:
            gae(batch)
            acted = student_rows(batch)  # DAgger's mixture: PPO learns from the student's steps
            if acted.shape[0] >= algo.minibatches:
                stats.update(ppo_update(loss, ppo_optim, acted, algo, gen, scale=algo.weights.w1,
                                        lagged=bool(cfg.collector.overlap)))
        clock["ppo"] = time.perf_counter()
        stats.update(distill(student, batch, cfg, distill_optim, prior_loss, gen))
        clock["distill"] = time.perf_counter()
        if mix is not None:
            stats["dagger/beta"] = float(mix.beta)
            stats["dagger/teacher_acted"] = float(batch.get(keys.TEACHER_ACTED).float().mean())
            done[0] += 1  # the next batch is collected with the next iteration's share
            mix.beta.fill_(teacher_share(done[0], algo.dagger_mix_iterations))
        marks = list(clock.items())
        stats.update({f"time/{k}": t1 - t0 for (_, t0), (k, t1) in zip(marks[:-1], marks[1:],
                                                                        strict=True)})
        return stats

    it = runner.learn(policy, functools.partial(make_student_env, cfg,
                                                          state_shapes=shapes),
                      update, stop, resume,
                      postfix=lambda s: {"imit": f"{s.get('distill/loss_action', np.nan):.3f}"})
    stop.exit_if_signalled(runner.checkpoint_path)
    return StudentRun(student=student, checkpoint=runner.checkpoint_path, csv=runner.csv_path,
                      mcap=runner.mcap_path, iterations=it, oracle=oracle_path)


def student_eval_env_fn(cfg: DictConfig, student: Student):
    """The benchmark's env factory for a student: the eval env, stage-2 sensors, state."""
    from legoh.eval.benchmark import eval_env_settings

    shapes = state_shapes(student)

    def make(run: int):
        run_cfg, num_envs, overrides = eval_env_settings(cfg, run)
        return make_student_env(run_cfg, num_envs, shapes, evaluation=True, **overrides)

    return make
