"""Stage 2's teacher: which oracle checkpoint a student learns from, and the small oracle
trained (or reused from ``artefacts/``) when none is given or shipped."""

from __future__ import annotations

import hashlib
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from legoh.config.algo import Stage
from legoh.policies.embodiment import with_checkpoint_body
from legoh.policies.oracle import oracle_stage_config
from legoh.policies.pretrained import resolve_checkpoint, shipped_oracle
from legoh.runs import RunFolderBusy, resume_command, wait_for_run
from legoh.train.oracle import train_oracle


def oracle_config(cfg: DictConfig) -> DictConfig:
    """The stage-1 config a stage-2 run needs: same robot, trail, env, sim and seed; oracle
    defaults with ``algo.oracle_frames`` as the budget."""
    return oracle_stage_config(cfg, total_frames=int(cfg.algo.oracle_frames))


def oracle_artefact_dir(cfg: DictConfig) -> Path:
    """``artefacts/oracle-<robot>-<trail>-<hash>``: the hash covers every setting that
    changes the oracle, so two stage-2 runs that need the same oracle share it."""
    stage1 = oracle_config(cfg)
    key = OmegaConf.to_yaml(OmegaConf.masked_copy(stage1, ["robot", "trail", "env", "sim",
                                                           "seed", "algo"]), resolve=True)
    digest = hashlib.sha256(key.encode()).hexdigest()[:10]
    return Path(cfg.artefacts) / f"oracle-{cfg.robot.name}-{cfg.trail.name}-{digest}"


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


def run_body(cfg: DictConfig, resume: str | None) -> DictConfig:
    """``cfg`` with the body a training run acts in: a resumed run keeps its checkpoint's
    feet; a student takes its teacher's (the teacher's labels hold on its own feet only);
    a new oracle run the config's (``legoh.policies.embodiment``)."""
    if resume:
        return with_checkpoint_body(cfg, resume)
    if cfg.algo.stage != Stage.oracle:
        return with_checkpoint_body(cfg, ensure_oracle(cfg))
    return cfg


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
