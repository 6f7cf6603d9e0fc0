"""The loop both training stages share (rsl_rl's OnPolicyRunner is the shape).

A stage builds its env, networks, optimisers and its ``update(batch) -> stats``; the runner
owns everything around the update: the collector, resuming, the per-iteration scalars,
CSV and MCAP logs, checkpoints, the progress bar, weight sync to collector workers, and the
graceful end on SIGINT / SIGTERM.

    runner = OnPolicyRunner(cfg, out_dir, env, models, optims, layout, "oracle.pt")
    start = runner.resume(resume, load=...)               # a killed run continues
    runner.learn(policy, make_env_fn, update, start, stop)
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from legoh import keys
from legoh.checkpoint import make_payload, restore_rng, save_checkpoint
from legoh.logs import McapLog, ScalarCSV
from legoh.runs import GracefulStop, iterations_left, mujoco_log_in, run_lock, warn_diverged
from legoh.train.collect import make_collector, mirror_curriculum, policy_device, sync_weights


@contextmanager
def training_session(cfg: DictConfig, out_dir: Path) -> Iterator[GracefulStop]:
    """What a training run holds while it lives: the run folder's lock, MuJoCo's log in
    the folder, the learner's torch threads, and the SIGINT / SIGTERM handler it yields."""
    from legoh.threads import torch_threads

    with (run_lock(out_dir), mujoco_log_in(out_dir), torch_threads(cfg.algo.torch_threads),
          GracefulStop() as stop):
        yield stop


@dataclass
class OnPolicyRunner:
    """Collect, update, log and checkpoint until ``cfg.algo.total_frames``.

    Args:
        cfg: the run config. out_dir: the run folder. env: the training env (stepped by the
        in-process collector; with workers it carries the curriculum). models / optims:
        what checkpoints hold, by name. layout: the observation layout checkpoints carry.
        checkpoint_name: the file in ``out_dir``. extra: more checkpoint fields.
        desc: the progress bar's label.
    """

    cfg: DictConfig
    out_dir: Path
    env: object
    models: dict
    optims: dict
    layout: dict
    checkpoint_name: str
    extra: dict | None = None
    desc: str = "train"
    iteration: int = 0
    _resolved: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.device = policy_device(self.cfg)  # the learner's
        self._resolved = OmegaConf.to_container(self.cfg, resolve=True, enum_to_str=True)

    @property
    def checkpoint_path(self) -> Path:
        return self.out_dir / self.checkpoint_name

    def checkpoint(self, iteration: int) -> None:
        """Models, optimisers, curriculum and RNG at ``iteration``, written atomically."""
        base = getattr(self.env, "base_env", self.env)
        save_checkpoint(self.checkpoint_path, make_payload(
            models=self.models, optimizers=self.optims, iteration=iteration,
            robot=self.cfg.robot.name, layout=self.layout, config=self._resolved,
            extra=self.extra,
            curriculum=base.curriculum_state()))

    def resume(self, state: dict) -> int:
        """Load a checkpoint's state (already read and checked) into the run; returns the
        iteration to continue from."""
        self.iteration = restore_training(state, self.models, self.optims, self.env)
        return self.iteration

    def learn(self, policy, make_env_fn: Callable, update: Callable[[object], dict],
              stop: GracefulStop, resumed: str | None = None,
              on_iteration: Callable | None = None,
              postfix: Callable[[dict], dict] | None = None) -> int:
        """Train until the frame budget; returns the last iteration.

        ``update(batch)`` gets each (envs, time) batch on the learner's device and returns
        its scalars. ``on_iteration(it, stats)`` runs after logging; True stops training.
        ``postfix(stats)``: extra progress-bar fields.
        """
        cfg, algo, env = self.cfg, self.cfg.algo, self.env
        frames_per_batch = algo.num_envs * algo.steps_per_env
        iterations = max(1, algo.total_frames // frames_per_batch)
        start = it = self.iteration
        left = iterations_left(start, iterations, frames_per_batch, algo.total_frames, resumed)
        collector = make_collector(cfg, make_env_fn, policy, frames_per_batch,
                                   left * frames_per_batch, env=env)
        csv = ScalarCSV(self.out_dir / "train.csv", resume=bool(resumed), until=start)
        mcap = McapLog(self.out_dir, stem="train")
        dt = getattr(env, "base_env", env).dt
        categories = getattr(env, "base_env", env).terrain.categories
        bar = tqdm(total=iterations, initial=start, desc=self.desc, unit="it")
        tick = time.perf_counter()
        for batch in stop.batches(collector):
            got = time.perf_counter()
            batch = batch.reshape(-1, batch.shape[-1]).to(self.device)  # (envs, time)
            stats = update(batch)
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
            ep = stats["episode_frames"]
            bar.set_postfix(fps=f"{stats['frames_per_s']:.0f}", reward=f"{stats['reward']:.3f}",
                            ep_len="-" if np.isnan(ep) else f"{ep * dt:.1f}s",
                            fell=f"{stats['fell_frac']:.2f}", **(postfix or dict)(stats))
            if on_iteration is not None and on_iteration(it, stats):
                self.checkpoint(it)
                break
        bar.close()
        collector.shutdown()
        csv.close()
        mcap.close()
        self.csv_path, self.mcap_path, self.iteration = csv.path, mcap.path, it
        if it == start or stop.signum:  # nothing trained, or a signal: leave a checkpoint
            self.checkpoint(it)
        return it


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
            end = ended & mine
            stats[f"fell/{name}"] = (float(nxt[keys.FELL][end].float().mean()) if end.any()
                                     else float("nan"))
    return stats


def restore_training(state: dict, models: dict, optims: dict, env) -> int:
    """Load a checkpoint's modules, optimisers, curriculum and RNG into a run; returns the
    iteration to continue from."""
    for name, module in models.items():
        module.load_state_dict(state["models"][name])
    for name, opt in optims.items():
        opt.load_state_dict(state["optimizers"][name])
    getattr(env, "base_env", env).load_curriculum_state(state["curriculum"])
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
    proprio = nxt[keys.PROPRIO]
    num_actions = batch["action"].shape[-1]
    mcap.log_trajectory(
        iteration,
        base_pos=nxt[keys.BASE_POS].numpy(),
        base_quat=nxt[keys.BASE_QUAT].numpy(),
        joint_pos=proprio[:, 6:6 + num_actions].numpy(),  # relative to the default pose
        goals=nxt[keys.EXPERT_GOALS].numpy(),
        dt=dt,
        env=env_index,
    )

