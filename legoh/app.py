"""Stage dispatch for ``run.py``: the composed config picks what runs."""

from pathlib import Path

from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig


def run(cfg: DictConfig) -> None:
    """Run ``cfg.mode`` in the Hydra run's output folder."""
    from legoh.config import Mode, validate

    validate(cfg)
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    mode = Mode(cfg.mode)
    if mode == Mode.stand:
        from legoh import stand

        stand.main(cfg, out_dir)
    elif mode == Mode.eval:
        from legoh.eval import cli

        cli.main(cfg, out_dir)
    else:
        train_and_evaluate(cfg, out_dir)


def train_and_evaluate(cfg: DictConfig, out_dir: Path) -> None:
    """The main job: train the stage ``cfg.algo`` asks for, benchmark it, print where
    everything went. A stage-2 algorithm first trains (or reuses) the oracle it needs."""
    from legoh.eval.benchmark import evaluate
    from legoh.eval.curves import plot_learning_curve

    if cfg.algo.name == "oracle":
        from legoh.train.oracle import train_oracle

        run = train_oracle(cfg, out_dir, resume=cfg.resume)
        result = evaluate(cfg, run.actor, out_dir, label="oracle")
    else:
        from legoh.train.unified import student_eval_env_fn, train_student

        run = train_student(cfg, out_dir, resume=cfg.resume)
        result = evaluate(cfg, run.student.policy, out_dir, label=cfg.algo.name,
                          env_fn=student_eval_env_fn(cfg, run.student))
        print(f"[legoh] oracle used:       {run.oracle}")
    print(Path(result["paths"]["markdown"]).read_text())
    print(f"[legoh] checkpoint:        {run.checkpoint}")
    print(f"[legoh] training log:      {run.csv} (CSV), {run.mcap} (MCAP)")
    curve = plot_learning_curve(run.csv, out_dir / "learning_curve.png")
    print(f"[legoh] learning curve:    {curve}")
    for name, path in result["paths"].items():
        print(f"[legoh] benchmark {name + ':':13s} {path}")
