"""Typed, read-only configuration: Hydra structured configs for every group.

Each option file under ``conf/<group>/`` starts from its schema
(``defaults: [/schema/<group>@_here_: ...]``), so a mistyped key or a wrong type fails at
composition, naming the key.
"""

import dataclasses
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, DictConfig, OmegaConf

from legoh.config.algo import LossWeights, OracleConfig, UnifiedConfig
from legoh.config.collector import CollectorConfig, RayCollectorConfig
from legoh.config.env import EnvConfig
from legoh.config.eval import EvalConfig
from legoh.config.ranges import check_ranges
from legoh.config.robot import CameraConfig, RobotConfig
from legoh.config.trail import TrailConfig

__all__ = ["CameraConfig", "CollectorConfig", "Config", "EnvConfig", "LossWeights",
           "OracleConfig", "PlayConfig", "RobotConfig", "SimConfig", "TrailConfig",
           "UnifiedConfig", "Viewer", "WebConfig", "register_configs", "validate"]


class Mode(Enum):
    """What ``run.py`` does with the composed config."""

    train = "train"
    eval = "eval"
    stand = "stand"
    export = "export"
    play = "play"


class Viewer(Enum):
    """How ``mode=play`` shows the policy (``viewer=...``)."""

    video = "video"  # play.mp4 and a filmstrip of robot 0 in the run folder
    web = "web"  # an interactive 3-D page served with viser until Ctrl-C (legoh/viewer)


@dataclass
class WebConfig:
    """Where ``viewer=web`` serves its page (``web.host``, ``web.port``)."""

    # 127.0.0.1: this machine only (reach a remote one through an SSH tunnel, ssh -L
    # 8080:localhost:8080); 0.0.0.0 serves every network the machine is on
    host: str = "127.0.0.1"
    port: int = 8080  # a taken port: the next free one is used; 0: any free port


@dataclass
class PlayConfig:
    """What ``mode=play`` rolls out and films (``play.robots``, ``play.film``)."""

    robots: int = 4  # robots rolled out on the level; the others give the mean DW
    # whose episode the video shows: a robot's index (0 .. robots-1), or an outcome
    # (fell | time-out | reached): the first robot whose episode ended so (robot 0 if none)
    film: str = "0"


@dataclass
class SimConfig:
    """Physics timing: the policy runs every ``dt * decimation`` seconds (50 Hz by default)."""

    dt: float = 0.005  # s, MuJoCo timestep
    decimation: int = 4  # physics steps per policy step
    threads: int = 0  # worker threads for batched stepping; 0: one per CPU core
    hfield_chunk: float = 4.0  # m, side of the height-field chunks (fast ray casts, docs/env.md)
    backend: str = "mujoco"  # physics: mujoco (CPU, mujoco.rollout) | warp (MuJoCo Warp)
    # MuJoCo Warp only (conf/sim/warp.yaml; docs/scaling.md)
    # auto: cuda when torch sees a GPU, else Warp's CPU device (slow: for tests and trying it)
    warp_device: str = "auto"  # auto | cuda | cuda:N | cpu
    nconmax: int = 64  # contacts allocated per world; overflow is reported, raise it then
    njmax: int = 320  # constraint rows allocated per world (4 per frictional contact)
    graph: bool = True  # capture the substeps as one CUDA graph (GPU only)
    overflow_check_every: int = 50  # policy steps between overflow checks (each syncs); 0: off


@dataclass
class Config:
    """The composed run config (``conf/config.yaml``)."""

    robot: Any = MISSING
    trail: Any = MISSING
    algo: Any = MISSING
    eval: Any = MISSING
    collector: Any = MISSING  # sync (this machine) | ray (Ray actors, a cluster)
    sim: SimConfig = field(default_factory=SimConfig)
    env: EnvConfig = field(default_factory=EnvConfig)
    # train (then evaluate), eval (a checkpoint), stand (a picture), export (a student to
    # one TorchScript file), play (a video of a checkpoint's oracle hiking)
    mode: Mode = Mode.train
    seed: int = 0
    device: str = "cpu"  # learner and policy: cpu | cuda | cuda:N | auto (envs: CPU)
    resume: str | None = None  # train: a checkpoint to continue from (a killed run resumes)
    # train: a new run (own folder, fresh optimiser, curriculum from level 0) starting from a
    # checkpoint's weights. "pretrained" (the default): the robot's shipped file of the stage
    # trained, pretrained/<robot>_oracle.pt (stage 1) or <robot>_<algo.name>.pt (a student:
    # its weights; the critic and the action prior are the teacher's), or from scratch when
    # it ships none; none: from scratch
    init: str | None = "pretrained"
    checkpoint: str | None = None  # eval, play: the policy; none: the untrained one
    viewer: Viewer = Viewer.video  # play: a video (video) or an interactive page (web)
    web: WebConfig = field(default_factory=WebConfig)  # viewer=web: where it serves
    play: PlayConfig = field(default_factory=PlayConfig)  # mode=play: robots, whom to film
    video: bool = True  # train: the main job ends with a video of its policy (play.mp4)
    stand_seconds: float = 3.0  # s mode=stand holds the default pose before rendering
    # where stage 2 keeps the oracles it trained, keyed by their config, for reuse
    artefacts: str = "artefacts"


def register_configs() -> None:
    """Store every schema in Hydra's ConfigStore (idempotent)."""
    cs = ConfigStore.instance()
    cs.store(name="base_config", node=Config)
    cs.store(group="schema/robot", name="robot", node=RobotConfig)
    cs.store(group="schema/trail", name="trail", node=TrailConfig)
    cs.store(group="schema/algo", name="oracle", node=OracleConfig)
    cs.store(group="schema/algo", name="unified", node=UnifiedConfig)
    cs.store(group="schema/eval", name="eval", node=EvalConfig)
    cs.store(group="schema/collector", name="sync", node=CollectorConfig)
    cs.store(group="schema/sim", name="sim", node=SimConfig)
    cs.store(group="schema/collector", name="ray", node=RayCollectorConfig)


def validate(cfg: DictConfig, path: str = "") -> None:
    """Refuse keys a schema does not declare, wherever they came from, and (on the whole
    config) numbers outside their valid range (:mod:`legoh.config.ranges`).

    Composition already rejects mistyped keys in files and plain overrides; this also catches
    Hydra's append syntax (``+robot.kpp=3``), which bypasses the schema.
    """
    schema = OmegaConf.get_type(cfg)
    if dataclasses.is_dataclass(schema):
        known = {f.name for f in dataclasses.fields(schema)}
        unknown = sorted(set(cfg.keys()) - known)
        if unknown:
            where = path or "config"
            raise ValueError(f"unknown key(s) {[f'{path}.{k}'.lstrip('.') for k in unknown]} "
                             f"in {where} ({schema.__name__} has: {sorted(known)})")
    for key in cfg.keys():
        child = cfg._get_node(key)
        if isinstance(child, DictConfig) and not child._is_none():
            validate(child, f"{path}.{key}".lstrip("."))
    if not path:
        check_ranges(cfg)
