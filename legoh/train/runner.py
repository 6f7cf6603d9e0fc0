"""The loop both training stages share (rsl_rl's OnPolicyRunner is the shape).

A stage builds its env and its :class:`legoh.train.algorithm.Algorithm` (networks,
optimisers, ``update(batch) -> stats``); the runner owns everything around the update: the
seed (:func:`training_session`), the collector, resuming, the per-iteration scalars, CSV
and MCAP logs, checkpoints, the progress bar, weight sync to collector workers, the
graceful end on SIGINT / SIGTERM and the :class:`Run` record.

    with training_session(cfg, out_dir) as stop:
        env = make_env(cfg, num_envs=cfg.algo.num_envs)
        runner = OnPolicyRunner(cfg, env, OraclePPO(cfg, env), out_dir, env_fn)
        runner.resume(path)                                # a killed run continues
        run = runner.learn(stop)
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from legoh import keys
from legoh.checkpoint import make_payload, restore_rng, save_checkpoint
from legoh.envs.mdp.observations import proprio_slice
from legoh.logs import McapLog, ScalarCSV
from legoh.runs import GracefulStop, iterations_left, mujoco_log_in, run_lock, warn_diverged
from legoh.threads import torch_threads
from legoh.train.algorithm import Algorithm
from legoh.train.collect import make_collector, mirror_curriculum, sync_weights


@contextmanager
def training_session(cfg: DictConfig, out_dir: Path) -> Iterator[GracefulStop]:
    """What a training run holds while it lives: the run folder's lock, MuJoCo's log in
    the folder, the learner's torch threads, and the SIGINT / SIGTERM handler it yields.
    Torch is seeded with ``cfg.seed`` on entry, before the stage builds its networks."""
    with (run_lock(out_dir), mujoco_log_in(out_dir), torch_threads(cfg.algo.torch_threads),
          GracefulStop() as stop):
        torch.manual_seed(cfg.seed)
        yield stop


@dataclass
class Run:
    """What a training run leaves behind."""

    algorithm: Algorithm
    checkpoint: Path
    csv: Path
    mcap: Path
    iterations: int

    @property
    def policy(self) -> torch.nn.Module:
        """The trained acting module (the oracle's actor, a student's policy)."""
        return self.algorithm.policy


class OnPolicyRunner:
    """Collect, update, log and checkpoint until ``cfg.algo.total_frames``.

    Args:
        cfg: the run config. env: the training env (stepped by the in-process collector;
            with workers it carries the curriculum). algorithm: the stage's learner.
        out_dir: the run folder. env_fn: ``env_fn(num_envs)`` builds an env like ``env``
            (picklable: collector workers call it).
    """

    def __init__(self, cfg: DictConfig, env, algorithm: Algorithm, out_dir: Path,
                 env_fn: Callable) -> None:
        self.cfg, self.env, self.algorithm, self.env_fn = cfg, env, algorithm, env_fn
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.iteration, self.resumed = 0, None
        self._resolved = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)

    @property
    def checkpoint_path(self) -> Path:
        return self.out_dir / f"{self.algorithm.name}.pt"

    def checkpoint(self, iteration: int) -> None:
        """The algorithm's state, curriculum and RNG at ``iteration``, written atomically."""
        save_checkpoint(self.checkpoint_path, make_payload(
            **self.algorithm.state_dict(), iteration=iteration, robot=self.cfg.robot.name,
            layout=self.algorithm.layout, config=self._resolved, extra=self.algorithm.extra,
            curriculum=self.env.curriculum_state()))

    def resume(self, path: str | Path) -> int:
        """Continue from checkpoint ``path`` (read and checked by the algorithm): models,
        optimisers, curriculum, RNG; returns the iteration to continue from."""
        state = self.algorithm.read_checkpoint(path)
        self.iteration = restore_training(state, self.algorithm, self.env)
        self.resumed = str(path)
        print(f"[legoh] resumed from {path} at iteration {self.iteration}")
        return self.iteration

    def learn(self, stop: GracefulStop, on_iteration: Callable | None = None,
              resume_hint: str | None = None) -> Run:
        """Train until the frame budget; returns the run's record.

        ``on_iteration(it, stats)`` runs after logging; True stops training. On SIGINT /
        SIGTERM the run ends after the iteration under way with a checkpoint and exits with
        the command that resumes it (``resume_hint``; default ``python run.py ...
        resume=<checkpoint>``).
        """
        cfg, algo, env, alg = self.cfg, self.cfg.algo, self.env, self.algorithm
        frames_per_batch = algo.num_envs * algo.steps_per_env
        iterations = max(1, algo.total_frames // frames_per_batch)
        start = it = self.iteration
        left = iterations_left(start, iterations, frames_per_batch, algo.total_frames,
                               self.resumed)
        collector = make_collector(cfg, self.env_fn, alg.policy, frames_per_batch,
                                   left * frames_per_batch, env=env)
        csv = ScalarCSV(self.out_dir / "train.csv", resume=bool(self.resumed), until=start)
        mcap = McapLog(self.out_dir, stem="train")
        dt = env.dt  # a stage-2 TransformedEnv forwards these to its HikingEnv
        categories = env.terrain.categories
        bar = tqdm(total=iterations, initial=start, desc=alg.label, unit="it")
        tick = time.perf_counter()
        for batch in stop.batches(collector):
            got = time.perf_counter()
            batch = batch.reshape(-1, batch.shape[-1]).to(alg.device)  # (envs, time)
            stats = alg.update(batch)
            stats["time/collect"], stats["time/update"] = got - tick, time.perf_counter() - got
            sync_weights(collector)  # workers act with the updated policy from the next batch
            mirror_curriculum(collector, env, batch)  # workers' levels -> checkpoint
            stats.update(batch_scalars(batch, categories))
            now = time.perf_counter()
            stats["frames_per_s"] = frames_per_batch / (now - tick)
            tick = now
            it += 1
            record_iteration(it, iterations, stats, batch, algo, csv, mcap, dt, self.checkpoint)
            bar.update(1)
            bar.set_postfix(progress_line(stats, it * frames_per_batch, dt, alg.progress(stats)))
            if on_iteration is not None and on_iteration(it, stats):
                self.checkpoint(it)
                break
        bar.close()
        collector.shutdown()
        csv.close()
        mcap.close()
        self.iteration = it
        if it == start or stop.signum:  # nothing trained, or a signal: leave a checkpoint
            self.checkpoint(it)
        stop.exit_if_signalled(self.checkpoint_path, resume_hint)
        return Run(algorithm=alg, checkpoint=self.checkpoint_path, csv=csv.path,
                   mcap=mcap.path, iterations=it)


def progress_line(stats: dict, frames: int, dt: float, extra: dict[str, str]) -> dict[str, str]:
    """The progress bar's fields: frames so far, frames/s, and over the episodes that ended
    in the iteration: metres walked toward the terminus, seconds, the share that fell."""
    ep, metres = stats["episode_frames"], stats["episode_metres"]
    none = np.isnan(ep)  # no episode ended in this iteration: nothing to say of them
    return {"frames": f"{frames / 1e6:.2f}M", "fps": f"{stats['frames_per_s']:.0f}",
            "walked": "-" if none else f"{metres:.1f}m", "ep": "-" if none else f"{ep * dt:.1f}s",
            "falls": "-" if none else f"{100 * stats['fell_frac']:.0f}%",
            "reward": f"{stats['reward']:.3f}", **extra}


def batch_scalars(batch, categories: list[str] | None = None) -> dict[str, float]:
    """Per-iteration means of what the env reported: rewards, each term, levels, outcomes,
    the randomisation strength, and (given the map's ``categories``, when it has more than
    one) the mean level and fall share per category."""
    nxt = batch["next"]
    done = nxt["done"].float()
    ended = nxt[keys.EPISODE_STEPS][nxt["done"].squeeze(-1)]
    stats = {
        "reward": float(nxt["reward"].mean()),
        # mean length of the episodes that ended in this batch; NaN when none did (the
        # frames-over-dones ratio it replaces read as the whole batch then)
        "episode_frames": float(ended.float().mean()) if ended.numel() else float("nan"),
        # metres of path each of those episodes covered toward its terminus
        "episode_metres": (float(nxt[keys.EPISODE_METRES][nxt["done"].squeeze(-1)].mean())
                           if ended.numel() else float("nan")),
        "level_mean": float(nxt[keys.LEVEL].float().mean()),
        "reached_frac": float(nxt[keys.REACHED].float().sum() / max(done.sum().item(), 1.0)),
        "fell_frac": float(nxt[keys.FELL].float().sum() / max(done.sum().item(), 1.0)),
        "diverged": float(nxt[keys.DIVERGED].sum()),  # envs reset for a diverged simulation
        "progress": float(nxt[keys.PROGRESS].float().mean()),
    }
    if keys.RANDOMIZATION[1] in nxt[keys.INFO].keys():
        ramp, alive, ended = nxt[keys.RANDOMIZATION].reshape(-1, 3)[-1].tolist()
        stats["randomization"] = ramp
        stats["gate_survival"] = alive / ended if ended > 0 else float("nan")
    for name, value in nxt[keys.REWARD_TERMS].items():
        stats[f"reward/{name}"] = float(value.mean())
    if categories is not None and len(categories) > 1:
        cat, level = nxt[keys.CATEGORY], nxt[keys.LEVEL].float()
        ended = nxt["done"].squeeze(-1)
        for i, name in enumerate(categories):
            mine = cat == i
            stats[f"level/{name}"] = float(level[mine].mean()) if mine.any() else float("nan")
            stats[f"share/{name}"] = float(mine.float().mean())  # the category mix
            end = ended & mine
            stats[f"fell/{name}"] = (float(nxt[keys.FELL][end].float().mean()) if end.any()
                                     else float("nan"))
            # every reward term per category: which terms a category's robots earn or pay
            for term, value in nxt[keys.REWARD_TERMS].items():
                stats[f"reward/{term}/{name}"] = (float(value[mine].mean()) if mine.any()
                                                  else float("nan"))
    return stats


def restore_training(state: dict, algorithm: Algorithm, env) -> int:
    """Load a checkpoint's models, optimisers, curriculum and RNG into a run; returns the
    iteration to continue from."""
    algorithm.load_state_dict(state)
    env.load_curriculum_state(state["curriculum"])
    restore_rng(state["rng"])
    return int(state["iteration"])


def record_iteration(it: int, iterations: int, stats: dict, batch, algo, csv: ScalarCSV,
                     mcap: McapLog, dt: float, checkpoint) -> None:
    """An iteration's scalars to CSV and MCAP; a trajectory every ``algo.trajectory_every``
    and a checkpoint (``checkpoint(it)``) every ``algo.checkpoint_every`` iterations and
    at the last one."""
    csv.write(it, stats)
    mcap.log_scalars(it, stats)
    warn_diverged(csv.path.parent, it, stats.get("diverged", 0.0))
    if it % algo.trajectory_every == 0 or it == iterations:
        log_trajectory(mcap, it, batch, dt)
    if it % algo.checkpoint_every == 0 or it == iterations:
        checkpoint(it)


def log_trajectory(mcap: McapLog, iteration: int, batch, dt: float, env_index: int = 0) -> None:
    """Record one robot's path through the batch (base pose, joints, goals) to MCAP."""
    nxt = batch["next"][env_index].cpu()
    joints = proprio_slice("joint_pos", batch["action"].shape[-1])
    mcap.log_trajectory(
        iteration,
        base_pos=nxt[keys.BASE_POS].numpy(),
        base_quat=nxt[keys.BASE_QUAT].numpy(),
        joint_pos=nxt[keys.PROPRIO][:, joints].numpy(),  # relative to the default pose
        goals=nxt[keys.EXPERT_GOALS].numpy(),
        dt=dt,
        env=env_index,
    )

