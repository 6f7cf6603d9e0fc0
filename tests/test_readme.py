"""README: what it promises about evaluations, and the files its commands leave behind."""

import dataclasses
import shutil
import subprocess
from pathlib import Path

import pytest

from legoh.config.eval import EvalConfig

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def test_readme_names_every_key_that_sizes_an_evaluation() -> None:
    """Failed before with: eval.robots (and every other eval.* key) not in README.md."""
    missing = [f"eval.{f.name}" for f in dataclasses.fields(EvalConfig)
               if f"eval.{f.name}" not in README]
    assert not missing


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(),
                    reason="needs the git checkout")
@pytest.mark.parametrize("path", ["trail/forest_l2_v0_s0.png", "terrain_out/x.npz",
                                  "MUJOCO_LOG.TXT", "outputs/2026-01-01/x/train.csv",
                                  "multirun/x/y", "artefacts/oracle-h1/oracle.pt"])
def test_files_readme_commands_write_are_git_ignored(path: str) -> None:
    """Failed before with: trail/, terrain_out/ and MUJOCO_LOG.TXT not ignored (`git status`
    listed them after running README's commands)."""
    done = subprocess.run(["git", "check-ignore", "-q", path], cwd=ROOT)
    assert done.returncode == 0, f"{path} is not git-ignored"


def test_readme_says_how_resume_uses_run_folders() -> None:
    """Failed before with: no word on which folder a resumed run writes to."""
    assert "continues in `<run>`, the checkpoint's own folder" in README
    assert "hydra.run.dir=..." in README
