"""Run bookkeeping (legoh/runs.py): a resumed run's budget, a clean stop on a signal."""

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from legoh.checkpoint import load_checkpoint

ROOT = Path(__file__).resolve().parents[1]
TINY_RUN = ("trail=flat", "trail.levels=1", "trail.variants=1", "algo.num_envs=4",
            "algo.steps_per_env=8", "algo.epochs=1", "algo.minibatches=2",
            "algo.total_frames=320000", "algo.checkpoint_every=1000",
            "algo.trajectory_every=1", "collector.overlap=false")  # as test_train_oracle's


def start_run(out: Path, *overrides: str, session: bool = False) -> subprocess.Popen:
    """``python run.py`` in a subprocess (a real process to signal), output into ``out``;
    ``session``: in a process group of its own (to signal it as a terminal does)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "run.py", *TINY_RUN, *overrides,
                             f"hydra.run.dir={out}"], cwd=ROOT, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=session)


def wait_for_rows(path: Path, rows: int, proc: subprocess.Popen, timeout: float = 240) -> None:
    """Until ``path`` (a CSV) holds ``rows`` data rows; fails if the run ends first."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.is_file() and len(path.read_text().splitlines()) > rows:
            return
        if proc.poll() is not None:
            pytest.fail(f"the run ended early:\n{proc.stdout.read()}")
        time.sleep(0.2)
    proc.kill()
    pytest.fail("the run wrote no rows in time")


@pytest.mark.parametrize("overlap", [False, True], ids=["turns", "overlap"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_leaves_a_checkpoint_closed_logs_and_the_resume_command(tmp_path, sig,
                                                                         overlap):
    """Ctrl-C (SIGINT) or SIGTERM mid-run: a final checkpoint at the last finished
    iteration, an MCAP the stock reader opens through its summary, the command to resume.
    With the overlap (the oracle's default) the signal goes to the whole process group, as
    a terminal's Ctrl-C or a job scheduler's SIGTERM does, collector worker included.

    Failed before with: SIGINT: KeyboardInterrupt traceback, no checkpoint (the periodic one
    was 1000 iterations away), an MCAP without summary; SIGTERM: killed outright, the same.
    Then, with the overlap: the worker died of the signal and the learner raised "the
    collector worker died" (SIGINT) or ConnectionResetError reading its batch (SIGTERM)."""
    out = tmp_path / "run"
    # 64 robots: the learner spends most of an iteration waiting for the worker's batch
    proc = start_run(out, *(["collector.overlap=true", "algo.num_envs=64"] if overlap
                            else []), session=overlap)
    wait_for_rows(out / "train.csv", 2, proc)
    if overlap:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    text, _ = proc.communicate(timeout=120)
    assert proc.returncode == 128 + sig, text
    with (out / "train.csv").open() as f:
        done = [int(row["iteration"]) for row in csv.DictReader(f)]
    assert load_checkpoint(out / "oracle.pt")["iteration"] == done[-1]
    with (out / "train-000.mcap").open("rb") as f:
        reader = make_reader(f)
        assert reader.get_summary() is not None  # finished: summary and footer written
        scalars = [m for _, ch, m in reader.iter_messages() if ch.topic == "scalars"]
    assert len(scalars) == len(done)
    assert f"python run.py {' '.join(TINY_RUN)}" in text
    assert f"resume={out / 'oracle.pt'}" in text


def test_a_second_run_into_a_held_folder_is_refused(tmp_path):
    """A run into the folder of a live run is refused at once, naming the folder.

    Failed before with: FileExistsError "... pass resume=True" (train.csv existed; nothing said
    a run was live); two runs started in the same instant both appended to one train.csv."""
    from legoh.train.oracle import train_oracle
    from tests.conftest import compose_config

    out = tmp_path / "run"
    proc = start_run(out)
    try:
        wait_for_rows(out / "train.csv", 1, proc)
        rows = len((out / "train.csv").read_text().splitlines())
        # legoh.runs.RunFolderBusy, a RuntimeError
        with pytest.raises(RuntimeError, match=rf"{out} is in use by another run \(pid "
                                                rf"{proc.pid}\)"):
            train_oracle(compose_config(*TINY_RUN), out)
        assert len((out / "train.csv").read_text().splitlines()) >= rows
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=120)


def test_default_run_folders_do_not_collide() -> None:
    """The default run and sweep folders go down to the microsecond.

    Failed before with: Hydra's default outputs/<date>/<H-M-S>: two runs started in the same
    second shared a folder."""
    from hydra import compose, initialize_config_dir

    from tests.conftest import CONF_DIR

    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        hydra_cfg = compose("config", return_hydra_config=True).hydra
    for node in (hydra_cfg.run, hydra_cfg.sweep):
        assert "%f" in str(node._get_node("dir")._value())


def test_resume_continues_in_the_checkpoints_folder_and_keeps_its_config(tmp_path):
    """``python run.py resume=<run>/oracle.pt`` writes into ``<run>``: its CSV continues,
    its ``.hydra/config.yaml`` stays the first run's, the benchmark lands beside them.

    Failed before with: the first folder's CSV stayed ['1']: the resumed run wrote into a
    new outputs/<date>/<time>/, splitting its history over two folders."""
    from legoh.train.oracle import train_oracle
    from tests.conftest import compose_config

    first = tmp_path / "first"
    tiny = [o for o in TINY_RUN if not o.startswith("algo.total_frames")]
    train_oracle(compose_config(*tiny, "algo.total_frames=32"), first)
    (first / ".hydra").mkdir()
    (first / ".hydra" / "config.yaml").write_text("# the first run's\n")
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run(
        [sys.executable, str(ROOT / "run.py"), *tiny, "algo.total_frames=64",
         f"resume={first / 'oracle.pt'}", "eval.robots=2", "eval.seconds=0.5", "eval.runs=1",
         "eval.levels=[0]", "eval.variants=1"],
        cwd=tmp_path, env=env, text=True, capture_output=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    with (first / "train.csv").open() as f:
        assert [row["iteration"] for row in csv.DictReader(f)] == ["1", "2"]
    assert (first / ".hydra" / "config.yaml").read_text() == "# the first run's\n"
    assert (first / "benchmark.md").is_file()
    assert load_checkpoint(first / "oracle.pt")["iteration"] == 2
