"""Where the envs step and where the learner runs: collectors and devices.

Every training stage asks this module for its collector, so the same loop runs with the
envs in its own process (``collector=sync``), in local worker processes
(``collector=sync collector.workers=K``: torchrl's MultiSyncCollector) or in Ray actors on
this machine or a cluster (``collector=ray collector.workers=K``: torchrl's RayCollector).
The learner stays in the main process on ``device``; after each update the trainer calls
``sync_weights`` so every worker acts with the new policy on the next batch.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from omegaconf import DictConfig
from torchrl.collectors import BaseCollector, Collector, MultiSyncCollector
from torchrl.envs import EnvBase

from legoh import keys
from legoh.envs.physics import physics_device
from legoh.train.pipeline import PipelinedCollector

GIB = 1024**3


def policy_device(cfg: DictConfig) -> torch.device:
    """The learner's device from ``cfg.device``: ``cpu``, ``cuda`` (or ``cuda:N``), ``auto``.

    ``auto`` picks the GPU when there is one. Asking for CUDA on a machine without one is
    an error, not a silent fall-back to the CPU.
    """
    name = str(cfg.device)
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(name)
    except RuntimeError as err:
        raise ValueError(f"device={name!r} is not a device; use cpu, cuda, cuda:N or auto"
                         ) from err
    if device.type == "cuda" and not torch.cuda.is_available():
        raise RuntimeError(f"device={name} was asked for, but torch sees no CUDA GPU here "
                           f"(torch {torch.__version__}); use device=cpu or device=auto")
    if device.type not in ("cpu", "cuda"):
        raise ValueError(f"device={name!r}: legoh runs on cpu or cuda")
    return device


def worker_policy_device(cfg: DictConfig) -> torch.device:
    """Where collector workers run the policy: ``collector.policy_device``, else the learner's."""
    name = cfg.collector.policy_device
    if name is None:
        return policy_device(cfg)
    return policy_device(DictConfig({"device": name}))


def envs_per_worker(cfg: DictConfig) -> int:
    """``algo.num_envs / collector.workers``; refuses a split that leaves envs over."""
    workers, num_envs = int(cfg.collector.workers), int(cfg.algo.num_envs)
    if workers < 1:
        raise ValueError(f"collector.workers={workers}: need at least one worker")
    if num_envs % workers:
        raise ValueError(f"algo.num_envs={num_envs} is not divisible by "
                         f"collector.workers={workers}: each worker steps the same number of "
                         f"envs")
    return num_envs // workers


def overlapped(cfg: DictConfig) -> bool:
    """Whether the run collects beside its update (``collector.overlap``; null: the stage's
    default). The oracle overlaps when it can (``collector=sync``, one worker, the learner
    on the CPU): its loop ran at 0.77-0.87 x the bare env at N = 256 against 0.62-0.70 in
    turns (three idle runs, ``bench_train.md``), and its learn curves with the overlap
    walked in the same frames (docs/oracle.md, attempts 7 and 9). Students do not: their
    lagged batches leave PPO ~1 % of their rows (docs/unified.md, "Speed")."""
    if cfg.collector.overlap is not None:
        return bool(cfg.collector.overlap)
    from legoh.config.algo import Stage

    return (cfg.algo.stage == Stage.oracle and cfg.collector.name == "sync"
            and int(cfg.collector.workers) == 1 and worker_policy_device(cfg).type == "cpu"
            and policy_device(cfg).type == "cpu" and physics_device(cfg.sim) == "cpu")


def make_collector(cfg: DictConfig, make_env_fn: Callable[[int], EnvBase], policy,
                   frames_per_batch: int, total_frames: int, env: EnvBase | None = None
                   ) -> BaseCollector | PipelinedCollector:
    """torchrl collector per ``cfg.collector``.

    ``make_env_fn(num_envs)`` builds one env copy; it must pickle (a functools.partial of a
    module-level function), since workers build their own. ``env``: an already built env
    with ``algo.num_envs`` envs, stepped in-process by the collector; with workers it only
    carries the curriculum: worker ``i`` starts from its slice of ``env``'s levels and step
    counter (a resumed run's), and :func:`mirror_curriculum` copies theirs back after each
    batch, so checkpoints keep the real one. Workers split ``algo.num_envs`` evenly. Each
    batch reshapes to (envs, time) with ``batch.reshape(-1, batch.shape[-1])`` and may sit
    on the CPU: the trainer moves it to ``policy_device(cfg)``.
    """
    per_worker = envs_per_worker(cfg)
    workers = int(cfg.collector.workers)
    if frames_per_batch % (per_worker * workers):
        raise ValueError(f"frames_per_batch={frames_per_batch} is not a whole number of steps "
                         f"of algo.num_envs={cfg.algo.num_envs} envs")
    kind = cfg.collector.name
    if kind == "sync":
        return _make_local(cfg, make_env_fn, policy, frames_per_batch, total_frames, env,
                           per_worker)
    if kind == "ray":
        if cfg.collector.overlap:  # set explicitly: a null never overlaps Ray
            raise ValueError("collector.overlap=true is for collector=sync (Ray actors already "
                             "collect apart from the learner)")
        return _make_ray(cfg, make_env_fn, policy, frames_per_batch, total_frames, per_worker,
                         env)
    raise ValueError(f"unknown collector {kind!r}; choose collector=sync or collector=ray")


def sync_weights(collector: BaseCollector | PipelinedCollector) -> None:
    """Send the learner's current policy weights to every worker (after each update).

    In-process the collector acts with the learner's own modules, so there is nothing to
    send; local workers and Ray actors each hold a copy that this refreshes.
    """
    if isinstance(collector, Collector):
        return
    collector.update_policy_weights_()


def _make_local(cfg, make_env_fn, policy, frames_per_batch, total_frames, env, per_worker
                ) -> BaseCollector:
    devices = {"env_device": torch.device(physics_device(cfg.sim)),
               "policy_device": worker_policy_device(cfg)}
    if overlapped(cfg):
        # one worker process collects batch k+1 with the weights of update k-1 while the
        # learner runs update k: the envs and the update share the cores instead of taking
        # turns (bench_train.md: loop / bare env); a fixed lag, so a seed's run repeats
        if cfg.collector.workers != 1:
            raise ValueError(f"collector.overlap=true takes collector.workers=1 (got "
                             f"{cfg.collector.workers}): one process overlaps its collection "
                             f"with the update")
        return PipelinedCollector(_worker_factories(make_env_fn, per_worker, 1, env)[0],
                                  policy, frames_per_batch, total_frames, int(cfg.seed),
                                  **devices)
    if cfg.collector.workers == 1:
        if env is None:
            env = make_env_fn(per_worker)
        return Collector(env, policy, frames_per_batch=frames_per_batch,
                         total_frames=total_frames,
                         auto_register_policy_transforms=False,  # the policies are stateless
                         # yield the collector's own buffer, not a copy of it: each batch is
                         # used up before the next is collected, and a student's batch
                         # (depth frames) is ~190 MB to copy (0.07-1 s an iteration)
                         return_same_td=True, **devices)
    collector = MultiSyncCollector(_worker_factories(make_env_fn, per_worker,
                                                     cfg.collector.workers, env), policy,
                                   frames_per_batch=frames_per_batch,
                                   total_frames=total_frames,
                                   auto_register_policy_transforms=False, **devices)
    collector.set_seed(cfg.seed)  # each worker's envs seeded apart
    return collector


def _make_ray(cfg, make_env_fn, policy, frames_per_batch, total_frames, per_worker, env
              ) -> BaseCollector:
    try:
        from torchrl.collectors.distributed import RayCollector
    except ImportError as err:  # pragma: no cover - torchrl always ships it
        raise ImportError("collector=ray needs torchrl's RayCollector") from err
    import importlib.util

    if importlib.util.find_spec("ray") is None:
        raise ImportError("collector=ray needs Ray: pip install -e '.[cluster]' "
                          "(or pip install ray)")
    ray_cfg = cfg.collector
    init = {key: value for key, value in ray_cfg.init.items() if value is not None}
    remote = {"num_cpus": ray_cfg.cpus_per_worker,
              "num_gpus": ray_cfg.gpus_per_worker or None,
              "memory": int(ray_cfg.memory_per_worker * GIB)}
    collector = RayCollector(
        _worker_factories(make_env_fn, per_worker, ray_cfg.workers, env), policy,
        frames_per_batch=frames_per_batch, total_frames=total_frames,
        env_device=torch.device(physics_device(cfg.sim)), policy_device=worker_policy_device(cfg),
        storing_device=torch.device("cpu"),
        collector_kwargs={"auto_register_policy_transforms": False},
        sync=True,  # one batch from every worker per iteration, stacked
        ray_init_config=init, remote_configs=remote)
    # torchrl defers the first weight transfer to the first update: do it before collecting
    collector.update_policy_weights_()
    collector.set_seed(cfg.seed)
    return collector


def mirror_curriculum(collector: BaseCollector | PipelinedCollector, env: EnvBase, batch) -> None:
    """With workers, copy their curriculum into the learner's (never stepped) ``env``: each
    env's level and category at the batch's last step and the step counter (+ the batch's T
    steps).

    ``batch`` is (envs, T), envs in worker order. A level that changes at the very last
    reset shows in the next batch: a checkpoint may lag it by one batch. In-process the
    collector steps ``env`` itself: nothing to do.
    """
    if isinstance(collector, Collector):
        return
    ramp, alive, ended = batch["next", keys.RANDOMIZATION][0, -1].tolist()
    env.load_curriculum_state({  # a stage-2 TransformedEnv forwards to its HikingEnv
        "level": batch["next", keys.LEVEL][:, -1],
        "category": batch["next", keys.CATEGORY][:, -1],  # moved by curriculum.lagging_mix
        "global_steps": env.curriculum_state()["global_steps"] + int(batch.shape[-1]),
        "randomization": {"ramp": ramp, "alive": alive, "ended": ended}})


def _worker_factories(make_env_fn, per_worker: int, workers: int, env: EnvBase | None
                      ) -> list[_WorkerEnv]:
    """One factory per worker; each carries its slice of ``env``'s curriculum (if given)."""
    if env is None:
        return [_WorkerEnv(make_env_fn, per_worker) for _ in range(workers)]
    state = env.curriculum_state()
    own = ("level", "category")  # per robot: each worker takes its slice
    return [_WorkerEnv(make_env_fn, per_worker, {
        **state, **{k: state[k][i * per_worker:(i + 1) * per_worker] for k in own if k in state}})
        for i in range(workers)]


class _WorkerEnv:
    """``make_env_fn(num_envs)`` as the zero-argument factory a remote collector calls; the
    env starts from ``curriculum`` (levels, step counter) when given."""

    def __init__(self, make_env_fn: Callable[[int], EnvBase], num_envs: int,
                 curriculum: dict | None = None) -> None:
        self.make_env_fn = make_env_fn
        self.num_envs = num_envs
        self.curriculum = curriculum

    def __call__(self) -> EnvBase:
        env = self.make_env_fn(self.num_envs)
        if self.curriculum is not None:
            env.load_curriculum_state(self.curriculum)
        return env
