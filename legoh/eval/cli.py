"""``mode=eval``: evaluate a checkpoint's actor (or an untrained one) with ``cfg.eval``."""

from __future__ import annotations

import warnings
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from legoh.config.algo import Stage
from legoh.eval.benchmark import evaluate, make_eval_env, student_eval_env_fn
from legoh.policies.embodiment import with_checkpoint_body
from legoh.policies.oracle import build_oracle, load_oracle_actor
from legoh.policies.pretrained import resolve_checkpoint, shipped_stage
from legoh.policies.student import sensors_from_checkpoint, student_from_checkpoint


def for_checkpoint(cfg: DictConfig, checkpoint: str | None) -> tuple[DictConfig, str | None]:
    """``checkpoint`` resolved (``pretrained``: the robot's shipped file for this algo,
    ``pretrained/<robot>_<oracle | algo name>.pt``) and ``cfg`` with the feet it trained on
    (:func:`with_checkpoint_body`) and, for a student, the camera and depth settings it was
    trained with (:func:`sensors_from_checkpoint`)."""
    if checkpoint == "pretrained":
        checkpoint = str(resolve_checkpoint(checkpoint, cfg.robot.name, shipped_stage(cfg)))
    if checkpoint:
        cfg = with_checkpoint_body(cfg, checkpoint)
    if checkpoint and cfg.algo.stage != Stage.oracle:
        cfg = sensors_from_checkpoint(cfg, checkpoint)
    return cfg, checkpoint


def build_actor(cfg: DictConfig, checkpoint: str | None = None):
    """The policy of ``cfg.algo`` with the weights of ``checkpoint`` (its robot, observation
    layout and, for a student, its student type must match this config; a student sees
    through its own camera: :func:`for_checkpoint`), and the env factory the benchmark
    needs for it (None: the plain evaluation env)."""
    cfg, checkpoint = for_checkpoint(cfg, checkpoint)
    if cfg.algo.stage != Stage.oracle:
        return build_student_policy(cfg, checkpoint)
    env = make_eval_env(OmegaConf.merge(cfg, {"eval": {"robots": 1}}))
    try:
        actor = (load_oracle_actor(cfg, checkpoint, env) if checkpoint
                 else build_oracle(env, cfg)[1])
    finally:
        env.close()
    return actor, None


def build_student_policy(cfg: DictConfig, checkpoint: str | None = None):
    """A stage-2 student (``cfg.algo.student``) and its evaluation env factory."""
    student = student_from_checkpoint(cfg, checkpoint)
    return student, student_eval_env_fn(cfg, student)


def main(cfg: DictConfig, out_dir: str | Path) -> dict:
    """Evaluate ``cfg.checkpoint``'s actor (when that key is set) with the protocol
    ``cfg.eval``; writes benchmark.md / benchmark.csv / trajectories.png to ``out_dir``."""
    checkpoint = OmegaConf.select(cfg, "checkpoint", default=None)
    if not checkpoint:
        warnings.warn("no checkpoint given (checkpoint=<path>): evaluating an untrained actor",
                      stacklevel=2)
        print("[legoh] WARNING: no checkpoint given, evaluating an untrained actor")
    cfg, checkpoint = for_checkpoint(cfg, checkpoint)  # the env of its own feet and camera
    policy, env_fn = build_actor(cfg, checkpoint)
    actor = policy.policy if env_fn is not None else policy
    label = Path(checkpoint).stem if checkpoint else "untrained"
    result = evaluate(cfg, actor, out_dir, label=label, env_fn=env_fn)
    print(Path(result["paths"]["markdown"]).read_text(encoding="utf-8"))
    print(f"[legoh] evaluation written to {Path(out_dir).resolve()} "
          f"({result['wall_s']:.0f} s, {result['steps']} policy steps)")
    return result
