"""Stage 2: a depth student (LEGO-H's unified policy or a baseline) learned from the oracle.

Read it top to bottom: :func:`train_student` picks the teacher (``train/teacher.py``),
builds the depth env and :class:`StudentDistillation`, and hands both to the runner. Per
iteration the student acts (DAgger), the frozen oracle labels the batch (actions and
scandot latent), the action prior (masked VAE for HLM) takes a few steps on the oracle's
actions, PPO updates the locomotion module on the Table 6 + point-navigation rewards, and
the imitation losses (action, latent, goals, HLM) update the whole student through time.
"""

from __future__ import annotations

import contextlib
import functools
import time
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig
from torch.nn.attention import SDPBackend, sdpa_kernel

from legoh import keys
from legoh.config.env import DepthConfig
from legoh.envs.hiking_env import make_env
from legoh.modules.actor_critic import LOC
from legoh.modules.encoders import PRIV_LATENT
from legoh.modules.students import Student, unroll
from legoh.objectives.distill import distillation_loss
from legoh.objectives.ppo import make_ppo, ppo_update, use_bfloat16
from legoh.policies.oracle import load_teacher
from legoh.policies.pretrained import init_checkpoint
from legoh.policies.student import (
    build_student,
    load_student,
    load_student_adding_history,
    make_student_env,
    read_student_checkpoint,
    state_shapes,
    stored_history_latent,
    student_env_overrides,
)
from legoh.train.algorithm import Algorithm, start_at_checkpoint_lr
from legoh.train.collect import overlapped, policy_device
from legoh.train.dagger import TeacherMix, student_rows, teacher_share
from legoh.train.prior import make_prior, pretrain_prior, train_prior
from legoh.train.runner import OnPolicyRunner, Run, training_session
from legoh.train.teacher import ensure_oracle, run_body


class StudentDistillation(Algorithm):
    """A student learning from a frozen oracle: DAgger labels, the action prior's steps,
    PPO on the locomotion module (``algo.ppo``), the imitation losses through time.

    Args:
        cfg: the run config. env: the stage-2 env (:func:`make_student_env`).
        student: the student acting in it. teacher: the frozen oracle actor and its critic
            (:func:`legoh.policies.oracle.load_teacher`). teacher_path: its checkpoint.
    """

    def __init__(self, cfg: DictConfig, env, student: Student, teacher: tuple,
                 teacher_path: Path, device: torch.device | None = None) -> None:
        algo = self.algo = cfg.algo
        self.cfg, self.student, self.teacher_path = cfg, student, teacher_path
        self.name, self.label = algo.name, f"{algo.name} ({algo.student})"
        self.device = device or policy_device(cfg)
        oracle, critic = teacher
        self.vae, vae_optim, self.prior_loss = make_prior(cfg, env.action_spec.shape[-1])
        for module in (*student.modules().values(), oracle, critic, self.vae):
            if module is not None:
                module.to(self.device)
        self.oracle = oracle
        # the student acts with its depth encoder in the update's precision (bfloat16:
        # 256 frames encoded in 87 ms against 136 in float32, 1 thread)
        student.navigation.frame_precision = functools.partial(
            precision_context, algo.update_precision, self.device.type)
        self.models = {**student.modules(), "critic": critic}
        self.loss, self.gae = make_ppo(student.locomotion, critic, algo)
        self.optimizers = {
            "ppo": torch.optim.Adam(self.loss.parameters(), lr=algo.lr),
            "distill": torch.optim.Adam(
                [p for m in student.modules().values() for p in m.parameters()], lr=algo.lr)}
        if self.vae is not None:
            self.models["vae"], self.optimizers["vae"] = self.vae, vae_optim
        self.layout = student.dims.as_layout()
        self.extra = {"student": algo.student, "oracle": str(teacher_path)}
        self.gen = torch.Generator().manual_seed(cfg.seed)
        self.updates = 0  # DAgger's share follows the updates done, resumed ones included
        self.mix, self.policy = None, student.policy
        if algo.dagger_mix_iterations > 0:
            self.mix = self.policy = TeacherMix(student.policy, oracle)
            self._set_share()

    def _set_share(self) -> None:
        if self.mix is not None:
            self.mix.beta.fill_(teacher_share(self.updates, self.algo.dagger_mix_iterations))

    def _set_distill_lr(self) -> float:
        """The imitation optimiser's learning rate for this update: ``algo.lr``, ramped
        linearly over the first ``algo.distill_warmup_iterations`` updates."""
        warmup = self.algo.distill_warmup_iterations
        lr = self.algo.lr * (min(1.0, (self.updates + 1) / warmup) if warmup > 0 else 1.0)
        for group in self.optimizers["distill"].param_groups:
            group["lr"] = lr
        return lr

    def update(self, batch) -> dict[str, float]:
        """Labels, prior steps, PPO on the student's own steps, then the imitation losses."""
        algo = self.algo
        clock = {"labels": time.perf_counter()}
        label_with_oracle(self.oracle, batch, algo.label_clip)
        stats = {}
        if self.vae is not None:
            teacher = batch.get(keys.TEACHER_ACTION)
            stats.update(train_prior(self.vae, self.optimizers["vae"],
                                     teacher.reshape(-1, teacher.shape[-1]), self.cfg, self.gen))
        clock["prior"] = time.perf_counter()
        if algo.ppo and algo.weights.w1:
            self.gae(batch)
            acted = student_rows(batch)  # DAgger's mixture: PPO learns from the student's steps
            if acted.shape[0] >= algo.minibatches:
                stats.update(ppo_update(self.loss, self.optimizers["ppo"], acted, algo, self.gen,
                                        scale=algo.weights.w1,
                                        lagged=overlapped(self.cfg)))
        clock["ppo"] = time.perf_counter()
        stats["distill/lr"] = self._set_distill_lr()
        stats.update(distill(self.student, batch, self.cfg, self.optimizers["distill"],
                             self.prior_loss, self.gen))
        clock["distill"] = time.perf_counter()
        if self.mix is not None:
            stats["dagger/beta"] = float(self.mix.beta)
            stats["dagger/teacher_acted"] = float(batch.get(keys.TEACHER_ACTED).float().mean())
        self.updates += 1
        self._set_share()  # the next batch is collected with the next iteration's share
        marks = list(clock.items())
        stats.update({f"time/{k}": t1 - t0 for (_, t0), (k, t1) in zip(marks[:-1], marks[1:],
                                                                        strict=True)})
        return stats

    def read_checkpoint(self, path: str | Path) -> dict:
        """A checkpoint of this student type, robot and layout."""
        return read_student_checkpoint(self.cfg, path, self.student)

    def warm_start(self, path: Path) -> None:
        """The student's weights from stage-2 checkpoint ``path`` (``init=``): same student,
        robot, layout and sensors (:func:`read_student_checkpoint` names a mismatch). The
        critic stays this teacher's, the optimisers and the action prior start afresh: the
        prior models the teacher's actions, and the teacher may be another one. PPO starts
        at the learning rate the checkpoint's schedule reached, as an oracle's warm start."""
        if self.algo.history_latent and not stored_history_latent(path):
            state = load_student_adding_history(self.cfg, path, self.student, self.teacher_path)
            print(f"[legoh] {path} has no history latent: its locomotion reads one now "
                  f"(zero weights to start), encoded by the teacher's adaptation module")
        else:
            state = load_student(self.cfg, path, self.student)
        start_at_checkpoint_lr(self.optimizers["ppo"], state)
        print(f"[legoh] student weights from {path} (init={self.cfg.init}, iteration "
              f"{state.get('iteration', '?')}; its teacher {state['extra'].get('oracle')}); "
              f"the teacher now {self.teacher_path}; PPO at lr "
              f"{self.optimizers['ppo'].param_groups[0]['lr']:.2e}")

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        self.updates = int(state.get("iteration", 0))
        self._set_share()

    def progress(self, stats: dict) -> dict[str, str]:
        return {"imit": f"{stats.get('distill/loss_action', np.nan):.3f}"}

    def pretrain_prior(self) -> None:
        """Pre-train the action prior on the oracle's own rollouts (``train/prior.py``)."""
        cfg, algo = self.cfg, self.algo
        if self.vae is None or algo.prior_pretrain_frames <= 0:
            return
        rollout_env = make_env(cfg, algo.num_envs, **{**student_env_overrides(cfg),
                                                       "depth": DepthConfig()})  # no frames
        out = pretrain_prior(self.vae, self.optimizers["vae"], rollout_env, self.oracle, cfg,
                             self.gen)
        rollout_env.close()
        print(f"[legoh] action prior pre-trained on {out['actions']} of the oracle's actions "
              f"({algo.prior_pretrain_steps} steps): reconstruction error "
              f"{out['recon_error_before']:.3f} -> {out['recon_error_after']:.3f} (each "
              f"joint's mean: {out['recon_error_mean_guess']:.3f})")


def label_with_oracle(oracle, batch, clip: float | None = None) -> None:
    """DAgger labels: the oracle's mean action (clamped to +-``clip`` unless None:
    ``algo.label_clip``), scandot latent and privileged latent on the student's states."""
    with torch.no_grad():
        out = oracle(batch.select(*oracle.in_keys).clone(recurse=False))
    action = out.get(LOC)
    batch.set(keys.TEACHER_ACTION, action if clip is None else action.clamp(-clip, clip))
    batch.set(keys.TEACHER_LATENT, out.get(keys.TEACHER_LATENT))
    batch.set(keys.TEACHER_PRIV_LATENT, out.get(PRIV_LATENT))


def distill(student: Student, batch, cfg: DictConfig, optim, prior_loss,
            gen: torch.Generator) -> dict:
    """``algo.distill_epochs`` passes over the batch in ``algo.minibatches`` groups of envs
    (whole sequences: the recurrent core runs through time), each pass over a random
    ``algo.distill_share`` of them; logged values are means. ``algo.update_precision``
    applies as in PPO (:func:`precision_context`)."""
    algo = cfg.algo
    n = batch.shape[0]
    groups = max(1, min(algo.minibatches, n))
    used = max(groups, round(algo.distill_share * n))
    sums: dict[str, float] = {}
    context = functools.partial(precision_context, algo.update_precision, batch.device.type)
    for _ in range(algo.distill_epochs):
        for rows in torch.randperm(n, generator=gen)[:used].chunk(groups):
            out = distill_step(student, batch[rows.to(batch.device)], cfg, optim, prior_loss,
                               context)
            for key, value in out.items():
                sums[key] = sums.get(key, 0.0) + value / (algo.distill_epochs * groups)
    return sums


def precision_context(precision, device_type: str) -> contextlib.AbstractContextManager:
    """The forward passes' precision (``algo.update_precision``, resolved as PPO resolves it):
    bfloat16 autocast, and on a CPU attention by the math kernel (its bfloat16 fused kernel
    ran slower than float32 on these tiny sequences: 4 frames, 12 patches), else nothing."""
    if not use_bfloat16(str(getattr(precision, "value", precision)), device_type):
        return contextlib.nullcontext()
    stack = contextlib.ExitStack()
    stack.enter_context(torch.autocast(device_type, dtype=torch.bfloat16))
    if device_type == "cpu":
        stack.enter_context(sdpa_kernel(SDPBackend.MATH))
    return stack


def distill_step(student: Student, batch, cfg: DictConfig, optim, prior_loss,
                 context=contextlib.nullcontext) -> dict:
    """One gradient step of the imitation losses over a (n, T) batch, the navigation
    module re-run through time (truncated BPTT over the batch's T steps) inside
    ``context()`` (the forward precision), and the prior's terms too; the losses are
    taken in float32."""
    with context():
        nav_out = unroll(student.navigation, batch)
        head_in = nav_out.clone(recurse=False)
        head_in.set(keys.PROPRIO, batch.get(keys.PROPRIO))
        loc = student.locomotion.module[0](head_in).get(LOC)  # the Gaussian head's mean
    nav_out, loc = nav_out.float(), loc.float()
    if prior_loss is not None:  # HLM's frozen VAE runs in the forward precision too
        prior_loss = functools.partial(_in_context, context, prior_loss)
    out = distillation_loss(nav_out, loc, batch, cfg.algo.weights, prior_loss)
    total = sum(v for k, v in out.items() if k.startswith("loss_"))
    optim.zero_grad()
    total.backward()
    params = [p for m in student.modules().values() for p in m.parameters()]
    torch.nn.utils.clip_grad_norm_(params, cfg.algo.max_grad_norm)
    optim.step()
    return {f"distill/{k}": float(v.detach()) for k, v in out.items() if v.numel() == 1}


def _in_context(context, prior_loss, teacher, student):
    """The prior's terms computed inside ``context()``, returned in float32 (bfloat16
    halved HLM's forward and backward: 1,536 rows 51 -> 27 ms, 2 threads)."""
    with context():
        out = prior_loss(teacher, student)
    return out.apply(lambda v: v.float())


def train_student(cfg: DictConfig, out_dir: Path, resume: str | None = None,
                  on_iteration=None, resume_hint: str | None = None) -> Run:
    """Train ``cfg.algo.student`` for ``cfg.algo.total_frames`` env steps; the record's
    ``algorithm`` holds the student and the teacher's path.

    ``on_iteration(it, stats, policy)``, if given, runs after each iteration is logged with
    the student's own policy (never DAgger's mixture with the teacher: what an evaluation
    should score); returning True stops training with a checkpoint. Signals and
    ``resume_hint`` as for :func:`legoh.train.oracle.train_oracle`.
    """
    if overlapped(cfg):
        print("[legoh] collector.overlap=true with a student: stable under decoupled PPO, but "
              "its lagged batches leave PPO ~1-2 % of their rows (ESS in train.csv) and "
              "imitated worse in the measured runs (docs/unified.md, 'Speed')")
    teacher_path = ensure_oracle(cfg)  # before the session: it may train an oracle of its own
    cfg = run_body(cfg, resume)
    with training_session(cfg, out_dir) as stop:
        student = build_student(cfg)
        shapes = state_shapes(student)
        env = make_student_env(cfg, cfg.algo.num_envs, shapes)
        algorithm = StudentDistillation(cfg, env, student, load_teacher(cfg, teacher_path, env),
                                        teacher_path)
        runner = OnPolicyRunner(cfg, env, algorithm, out_dir,
                                functools.partial(make_student_env, cfg, state_shapes=shapes))
        if resume:
            runner.resume(resume)
        else:
            if (init := init_checkpoint(cfg.init, cfg.robot.name, cfg.algo.name)) is not None:
                algorithm.warm_start(init)
            algorithm.pretrain_prior()
        hook = None if on_iteration is None else (
            lambda it, stats: on_iteration(it, stats, student.policy))
        return runner.learn(stop, on_iteration=hook, resume_hint=resume_hint)
