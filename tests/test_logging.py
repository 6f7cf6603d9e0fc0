"""CSV and MCAP run logs: columns, rows, channels, schemas, message counts, resume."""

import csv
import json
import math

import numpy as np
import pytest
from mcap.reader import make_reader

from legoh.logs import McapLog, ScalarCSV, read_mcap


def rows(path) -> list[list[str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.reader(f))


class TestScalarCSV:
    def test_header_then_rows(self, tmp_path):
        with ScalarCSV(tmp_path / "s.csv") as log:
            log.write(0, {"loss": 1.5, "reward": 0.25})
            log.write(1, {"reward": 0.5})  # a missing scalar is an empty cell
        assert rows(tmp_path / "s.csv") == [["iteration", "loss", "reward"],
                                            ["0", "1.5", "0.25"], ["1", "", "0.5"]]

    def test_new_column_widens_the_header(self, tmp_path):
        # a campaign resumed by newer code logs a new scalar: it used to stop the run
        with ScalarCSV(tmp_path / "s.csv") as log:
            log.write(0, {"loss": 1.0})
        with ScalarCSV(tmp_path / "s.csv", resume=True) as log:
            log.write(1, {"loss": 2.0, "kl": 0.1})
        assert rows(tmp_path / "s.csv") == [["iteration", "loss", "kl"], ["0", "1.0", ""],
                                            ["1", "2.0", "0.1"]]

    def test_cells_at_float32_precision_and_counts_exact(self, tmp_path):
        # Python's 17-digit text of float32 losses made a study job's train.csv 26 MB
        loss = float(np.float32(0.30052083))  # as a float32 tensor's .item() gives it
        with ScalarCSV(tmp_path / "s.csv") as log:
            log.write(0, {"loss": loss, "fps": 467.38330150712534, "frames": 26_900_012.0,
                          "kl": float("nan"), "huge": 1e300})
        (_, *values), = rows(tmp_path / "s.csv")[1:]
        assert dict(zip(rows(tmp_path / "s.csv")[0][1:], values, strict=True)) == {
            "fps": "467.3833", "frames": "26900012.0", "huge": "1e+300", "kl": "nan",
            "loss": "0.30052084"}
        assert np.float32(float(values[-1])) == np.float32(loss)  # reads back exactly

    def test_resume_appends_and_fresh_refuses(self, tmp_path):
        with ScalarCSV(tmp_path / "s.csv") as log:
            log.write(0, {"loss": 1.0})
        (tmp_path / "oracle.pt").touch()
        with pytest.raises(FileExistsError) as err:
            ScalarCSV(tmp_path / "s.csv")
        # the hint names the real command (it said "pass resume=True", a Python argument)
        assert "resume=True" not in str(err.value)
        assert f"python run.py <its overrides> resume={tmp_path / 'oracle.pt'}" in str(err.value)
        with ScalarCSV(tmp_path / "s.csv", resume=True) as log:
            log.write(1, {"loss": 2.0})
        assert rows(tmp_path / "s.csv") == [["iteration", "loss"], ["0", "1.0"], ["1", "2.0"]]

    def test_rows_are_flushed_before_close(self, tmp_path):
        log = ScalarCSV(tmp_path / "s.csv")
        log.write(0, {"loss": 1.0})
        assert len(rows(tmp_path / "s.csv")) == 2  # readable while still open
        log.close()


def trajectory(steps: int = 5, joints: int = 19):
    t = np.arange(steps, dtype=float)
    return dict(base_pos=np.stack([t, 0 * t, 1 + 0 * t], 1),
                base_quat=np.tile([1.0, 0, 0, 0], (steps, 1)),
                joint_pos=np.zeros((steps, joints)), goals=np.ones((steps, 3, 2)), dt=0.02)


class TestMcap:
    def test_channels_schemas_and_counts(self, tmp_path):
        with McapLog(tmp_path) as log:
            for it in range(3):
                log.log_scalars(it, {"loss": 0.5 * it, "kl": float("nan")})
            log.log_trajectory(2, env=7, **trajectory(5))
        with open(log.path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            topics = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
            assert set(topics) == {"scalars", "trajectory"}
            assert all(s.encoding == "jsonschema" for s in topics.values())
            assert "base_quat" in json.loads(topics["trajectory"].data)["properties"]
            counts = {summary.channels[k].topic: v
                      for k, v in summary.statistics.channel_message_counts.items()}
            assert counts == {"scalars": 3, "trajectory": 5}
            msgs = [(c.topic, json.loads(m.data)) for _, c, m in reader.iter_messages()]
        scal = [m for t, m in msgs if t == "scalars"]
        assert [m["iteration"] for m in scal] == [0, 1, 2]
        assert scal[1]["scalars"] == {"loss": 0.5, "kl": None}
        steps = [m for t, m in msgs if t == "trajectory"]
        assert steps[3]["base_pos"] == [3.0, 0.0, 1.0] and steps[3]["env"] == 7
        assert math.isclose(steps[3]["time"], 0.06) and len(steps[0]["goals"]) == 3

    def test_new_segment_per_process_start(self, tmp_path):
        paths = []
        for _ in range(2):
            with McapLog(tmp_path, stem="run") as log:
                log.log_scalars(0, {"x": 1.0})
            paths.append(log.path.name)
        assert paths == ["run-000.mcap", "run-001.mcap"]

    def test_killed_run_keeps_what_was_written(self, tmp_path):
        log = McapLog(tmp_path)
        log.log_scalars(0, {"x": 1.0})
        log.log_trajectory(0, **trajectory(4))
        # no close(): as if the process were killed; the file has no footer
        got = list(read_mcap(log.path))
        assert [t for t, _, _ in got] == ["scalars"] + ["trajectory"] * 4
        assert got[0][1] == "legoh.Scalars"
        log.close()
        assert len(list(read_mcap(log.path))) == 5

    def test_mismatched_trajectory_refused(self, tmp_path):
        traj = trajectory(4)
        traj["goals"] = traj["goals"][:3]
        with McapLog(tmp_path) as log, pytest.raises(ValueError, match="differ in length"):
            log.log_trajectory(0, **traj)
