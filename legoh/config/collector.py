"""Collector config schemas (``conf/collector/*.yaml``): where the envs step.

``sync``: in the learner's process (``workers=1``) or in ``workers`` local processes
(torchrl's MultiSyncCollector). ``ray``: in ``workers`` Ray actors, on this machine or on a
Ray cluster (torchrl's RayCollector). Either way ``algo.num_envs`` is split evenly among
the workers, the learner stays in the main process and the policy weights are sent to the
workers after every update. docs/scaling.md explains each setting.
"""

from dataclasses import dataclass, field


@dataclass
class CollectorConfig:
    """Local collection: ``workers=1`` steps the envs in the learner's own process."""

    name: str = "sync"
    workers: int = 1  # collector processes; algo.num_envs is split evenly among them
    # where the workers run the policy: None follows the learner (top-level ``device``);
    # the envs always step on the CPU (MuJoCo)
    policy_device: str | None = None
    # collect the next batch in a worker process while the learner updates (policy lag of
    # one update, decoupled PPO corrects for it); workers=1 only. null: the stage decides
    # (legoh.train.collect.overlapped): on for the oracle on a CPU learner (the loop at
    # 0.77-0.87 x the bare env at N = 256 against 0.62-0.70 in turns), off for students
    overlap: bool | None = None


@dataclass
class RayInitConfig:
    """Arguments of ``ray.init`` (used only when this process has not started Ray itself)."""

    address: str | None = None  # None: a new local cluster; "auto" or "HOST:PORT": join one
    num_cpus: int | None = None  # new local cluster only: CPUs Ray may schedule (None: all)
    include_dashboard: bool = False
    log_to_driver: bool = False  # true: print the workers' output here (errors come anyway)


@dataclass
class RayCollectorConfig(CollectorConfig):
    """Ray actors (torchrl's RayCollector, synchronous: one stacked batch per iteration)."""

    name: str = "ray"
    workers: int = 2
    policy_device: str | None = "cpu"  # workers may sit on nodes without a GPU
    cpus_per_worker: float = 1.0  # Ray resources each worker actor reserves
    gpus_per_worker: float = 0.0
    memory_per_worker: float = 2.0  # GiB reserved per worker actor
    init: RayInitConfig = field(default_factory=RayInitConfig)
