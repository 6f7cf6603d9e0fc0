"""SLURM sweeps: conf/hydra/launcher/slurm.yaml composes onto submitit's launcher, and the
settings it holds are ones submitit turns into sbatch directives."""

import os
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from tests.conftest import CONF_DIR

pytest.importorskip("hydra_plugins.hydra_submitit_launcher",
                    reason="hydra-submitit-launcher is not installed (pip install -e '.[dev]')")

SLURM_TARGET = "hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher"


def compose_with_hydra(*overrides: str):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose("config", overrides=list(overrides), return_hydra_config=True)


def test_slurm_launcher_composes_with_a_sweep() -> None:
    cfg = compose_with_hydra("hydra/launcher=slurm", "+experiment=ablation_temporal",
                             "hydra.launcher.partition=gpu", "hydra.launcher.gpus_per_node=1",
                             "device=cuda", "collector.workers=4")
    launcher = cfg.hydra.launcher
    assert launcher._target_ == SLURM_TARGET
    assert (launcher.partition, launcher.gpus_per_node) == ("gpu", 1)
    assert launcher.cpus_per_task == 16 and launcher.timeout_min == 720
    assert cfg.hydra.runtime.choices["hydra/launcher"] == "slurm"
    assert cfg.device == "cuda" and cfg.collector.workers == 4  # the run config is untouched


def test_a_mistyped_launcher_setting_fails() -> None:
    from hydra.errors import ConfigCompositionException

    with pytest.raises(ConfigCompositionException):
        compose_with_hydra("hydra/launcher=slurm", "hydra.launcher.partiton=gpu")


def test_submitit_writes_the_settings_into_the_sbatch_script(tmp_path: Path,
                                                             monkeypatch) -> None:
    """The launcher's own mapping of our settings, fed to submitit's SLURM executor (a stub
    ``srun`` on PATH stands in for a cluster; nothing is submitted)."""
    import submitit
    from hydra_plugins.hydra_submitit_launcher.config import BaseQueueConf

    stub = tmp_path / "bin" / "srun"
    stub.parent.mkdir()
    stub.write_text("#!/bin/sh\nexit 0\n")
    stub.chmod(0o755)
    monkeypatch.setenv("PATH", f"{stub.parent}{os.pathsep}{os.environ['PATH']}")

    cfg = compose_with_hydra("hydra/launcher=slurm", "hydra.launcher.partition=gpu",
                             "hydra.launcher.gpus_per_node=1", "hydra.job.name=legoh")
    params = OmegaConf.to_container(cfg.hydra.launcher, resolve=False)
    params.pop("_target_")
    params.pop("submitit_folder")
    executor = submitit.AutoExecutor(cluster="slurm", folder=tmp_path / "jobs",
                                     slurm_max_num_timeout=params.pop("max_num_timeout"))
    base = set(OmegaConf.structured(BaseQueueConf).keys())
    params["name"] = "legoh"
    executor.update_parameters(**{k if k in base else f"slurm_{k}": v
                                  for k, v in params.items()})
    script = executor._executor._make_submission_file_text("python run.py", "0")
    for line in ("#SBATCH --partition=gpu", "#SBATCH --cpus-per-task=16",
                 "#SBATCH --gpus-per-node=1", "#SBATCH --time=720", "#SBATCH --mem=32GB"):
        assert line in script, line
