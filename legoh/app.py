"""Stage dispatch for ``run.py``: the composed config picks what runs."""

from pathlib import Path

from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from legoh.config.algo import Stage


def run(cfg: DictConfig) -> None:
    """Run ``cfg.mode`` in the Hydra run's output folder (a resumed training run: in its
    checkpoint's folder, :func:`legoh.runs.run_folder`)."""
    from legoh.config import Mode, Viewer, validate
    from legoh.runs import run_folder

    validate(cfg)
    hydra = HydraConfig.get()
    mode = Mode(cfg.mode)
    out_dir = run_folder(mode.value, cfg.resume, Path(hydra.runtime.output_dir),
                         hydra.overrides.hydra)
    if mode == Mode.stand:
        from legoh import stand

        stand.main(cfg, out_dir)
    elif mode == Mode.eval:
        from legoh.eval import cli

        cli.main(cfg, out_dir)
    elif mode == Mode.export:
        export(cfg, out_dir)
    elif mode == Mode.play and Viewer(cfg.viewer) == Viewer.web:
        from legoh.viewer import cli as viewer

        viewer.main(cfg, hydra.overrides.task)
    elif mode == Mode.play:
        from legoh import play

        play.main(cfg, out_dir)
    else:
        train_and_evaluate(cfg, out_dir)


def train_and_evaluate(cfg: DictConfig, out_dir: Path) -> None:
    """The main job: train the stage ``cfg.algo`` asks for, benchmark it, print where
    everything went. A stage-2 algorithm first trains (or reuses) the oracle it needs."""
    from legoh.eval.benchmark import evaluate
    from legoh.eval.curves import plot_learning_curve
    from legoh.train.teacher import run_body

    cfg = run_body(cfg, cfg.resume)  # the feet it trains on: its checkpoint's or teacher's
    if cfg.algo.stage == Stage.oracle:
        from legoh.train.oracle import train_oracle

        run = train_oracle(cfg, out_dir, resume=cfg.resume)
        result = evaluate(cfg, run.policy, out_dir, label=cfg.algo.name)
    else:
        from legoh.eval.benchmark import student_eval_env_fn
        from legoh.export import export_student
        from legoh.train.unified import train_student

        run = train_student(cfg, out_dir, resume=cfg.resume)
        student = run.algorithm.student
        result = evaluate(cfg, student.policy, out_dir, label=cfg.algo.name,
                          env_fn=student_eval_env_fn(cfg, student))
        print(f"[legoh] oracle used:       {run.algorithm.teacher_path}")
        deployed = export_student(student, out_dir / "policy.ts", meta=export_meta(cfg))
        print(f"[legoh] deployable policy: {deployed} (TorchScript, docs/unified.md)")
    print(Path(result["paths"]["markdown"]).read_text())
    print_beside_shipped(cfg, result)
    print(f"[legoh] checkpoint:        {run.checkpoint}")
    print(f"[legoh] training log:      {run.csv} (CSV), {run.mcap} (MCAP)")
    curve = plot_learning_curve(run.csv, out_dir / "learning_curve.png",
                                title=f"{cfg.algo.name} ({cfg.robot.name}, {cfg.trail.name})",
                                frames_per_iteration=cfg.algo.num_envs * cfg.algo.steps_per_env,
                                dt=cfg.sim.dt * cfg.sim.decimation)
    print(f"[legoh] learning curve:    {curve}")
    for name, path in result["paths"].items():
        print(f"[legoh] benchmark {name + ':':13s} {path}")
    if cfg.video:
        from legoh.play import render_policy_video

        level = max(cfg.eval.levels)  # the level the trajectories picture shows
        if cfg.algo.stage == Stage.oracle:
            film = render_policy_video(cfg, run.policy, out_dir / "play.mp4", level=level)
        else:  # the student's own policy, its depth view beside the robot
            film = render_policy_video(cfg, student.policy, out_dir / "play.mp4", level=level,
                                       student=student)
        sr = result["levels"].get(f"level {level}", {}).get("SR", (float("nan"),))[0]
        print(f"[legoh] video:             {film['video']} (robot 0 on level {level}: "
              f"{film['distance']:.1f} m toward the terminus, "
              f"{'fell' if film['fell'] else 'did not fall'}; the benchmark's SR on that "
              f"level: {sr:.0f} %; filmstrip {film['filmstrip']})")


def print_beside_shipped(cfg: DictConfig, result: dict) -> None:
    """This run's overall and per-level rows beside the shipped oracle's on the same
    protocol (its card records them), when it has them: for an oracle the file it started
    from, for a student its default teacher."""
    from legoh.eval.metrics import to_markdown
    from legoh.policies.pretrained import shipped_reference

    ref = shipped_reference(cfg, "oracle")
    if ref is None:
        return
    mine = {**result["rows"], **result["levels"]}
    rows = {}
    for name in ref:
        if name in mine:
            rows[f"{name}: this run"] = mine[name]
            rows[f"{name}: shipped {cfg.robot.name}_oracle.pt"] = {
                k: tuple(v) for k, v in ref[name].items()}
    role = "oracle" if cfg.algo.stage == Stage.oracle else "oracle (the teacher by default)"
    print(to_markdown(rows, "Row", f"This run beside the shipped {cfg.robot.name} {role} "
                                   "(pretrained/, the same protocol and seed)"))


def export_meta(cfg: DictConfig) -> dict:
    """What a deployment needs besides the network: robot, action scale, the depth rate and
    frame window (keep the last ``depth_history`` frames, feed every ``depth_stride``-th
    counting back from the newest, oldest first)."""
    from legoh.envs.robots import build_robot_spec

    _, info = build_robot_spec(OmegaConf.to_object(cfg.robot))
    return {"robot": cfg.robot.name, "action_scale": info.action_scale.tolist(),
            "action_clip": float(cfg.env.action_clip), "policy_hz": 1.0 / (
                cfg.sim.dt * cfg.sim.decimation),
            "depth_every": int(cfg.env.depth.every),
            "depth_history": int(cfg.env.depth.history),
            "depth_stride": int(cfg.env.depth.stride), "algo": cfg.algo.name}


def export(cfg: DictConfig, out_dir: Path) -> Path:
    """``mode=export``: the student of ``checkpoint`` as one TorchScript file."""
    from legoh.export import export_student
    from legoh.policies.student import sensors_from_checkpoint, student_from_checkpoint

    if cfg.algo.stage == Stage.oracle:
        raise ValueError("mode=export deploys a depth student (algo=unified, ep_h, ...); "
                         "the oracle needs privileged inputs a robot does not have")
    if not cfg.checkpoint:
        raise ValueError("mode=export needs checkpoint=<path to a stage-2 checkpoint>")
    cfg = sensors_from_checkpoint(cfg, cfg.checkpoint)  # the meta: its own camera and depth
    student = student_from_checkpoint(cfg, cfg.checkpoint)
    path = export_student(student, out_dir / "policy.ts", meta=export_meta(cfg))
    print(f"[legoh] exported {cfg.checkpoint} to {path}")
    return path
