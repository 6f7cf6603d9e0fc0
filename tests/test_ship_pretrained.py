"""ship_pretrained: the clock lookup (an averaged snapshot ships with the minutes of its
last snapshot, not the run's end) and a candidate's table beside the shipped files."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
from ship_pretrained import beside_shipped, candidate_dir, clock_minutes  # noqa: E402

from legoh.eval.protocol import ProtocolMismatch  # noqa: E402


def test_clock_minutes_reads_the_row_at_or_before_the_iteration(tmp_path):
    clock = tmp_path / "clock.csv"
    clock.write_text("iteration,minutes\n0.0,0.0\n10,5.5\n20,11.0\n30,16.5\n")
    assert clock_minutes(clock, 30, None) == 16.5
    assert clock_minutes(clock, 25, None) == 11.0  # between rows: the earlier one
    assert clock_minutes(clock, 99, None) == 16.5
    assert clock_minutes(tmp_path / "missing.csv", 20, 7.0) == 7.0
    clock.write_text("iteration,minutes\n10,5.5\n")
    with pytest.raises(SystemExit, match="no row at or before iteration 3"):
        clock_minutes(clock, 3, None)


def test_a_candidate_is_tabled_beside_the_shipped_student_and_the_teacher(tmp_path):
    """Each category's SR from each benchmark.csv, and the candidate's ratio to the
    teacher's; files of two protocols are refused."""
    def bench(name: str, rows: dict[str, float], protocol: str = "v2") -> Path:
        path = tmp_path / f"{name}.csv"
        lines = ["category,SR (%) ↑ mean,SR (%) ↑ std,protocol"]
        lines += [f"{cat},{sr},1.5,{protocol}" for cat, sr in rows.items()]
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")
        return path

    files = {"candidate": bench("c", {"gap": 40.0, "overall": 54.0, "level 0": 90.0}),
             "shipped": bench("s", {"gap": 31.875, "overall": 50.625}),
             "teacher": bench("t", {"gap": 48.75, "overall": 60.0})}
    table = beside_shipped(files).splitlines()
    assert table[0] == ("| category | candidate SR (%) | shipped SR (%) | teacher SR (%) | "
                        "candidate / teacher |")
    assert table[2] == "| gap | 40.00 ± 1.50 | 31.88 ± 1.50 | 48.75 ± 1.50 | 0.82 |"
    assert table[3].endswith("| 0.90 |") and len(table) == 4  # no level rows
    files["shipped"] = bench("old", {"gap": 30.0}, protocol="v1")
    with pytest.raises(ProtocolMismatch):
        beside_shipped(files)


def test_a_candidate_scored_on_more_runs_than_a_card_is_named_so(tmp_path):
    """A candidate's folder names runs and robots that differ from the card's (2 runs, 80
    robots). Failed before: a 4-run score of pretrained/g1_oracle.pt went to
    ship_protocol_g1_oracle/, read as the card's protocol."""
    from types import SimpleNamespace

    src = Path("pretrained/g1_oracle.pt")
    card = SimpleNamespace(runs=2, robots=80)
    assert candidate_dir(tmp_path, src, card) == tmp_path / "ship_protocol_g1_oracle"
    assert (candidate_dir(tmp_path, src, SimpleNamespace(runs=4, robots=80))
            == tmp_path / "ship_protocol_g1_oracle-runs4")
    assert (candidate_dir(tmp_path, src, SimpleNamespace(runs=1, robots=16))
            == tmp_path / "ship_protocol_g1_oracle-runs1-robots16")


def test_a_ratio_to_the_teacher_is_read_on_as_many_runs(tmp_path):
    """Each column names its runs (benchmark_runs.csv beside the file); a 4-run candidate
    gets no ratio to a 2-run teacher. Failed before: 58.5 % on 4 runs over 66.5 % on 2 read
    0.88 x in one column, unmarked (journal 2026-12-12)."""
    def bench(name: str, sr: float, runs: int) -> Path:
        folder = tmp_path / name
        folder.mkdir()
        (folder / "benchmark.csv").write_text(
            f"category,SR (%) ↑ mean,SR (%) ↑ std,protocol\noverall,{sr},2.0,v2\n",
            encoding="utf-8")
        (folder / "benchmark_runs.csv").write_text(
            "run,category,SR (%) ↑,protocol\n"
            + "".join(f"{r},overall,{sr},v2\n" for r in range(runs)), encoding="utf-8")
        return folder / "benchmark.csv"

    files = {"candidate": bench("c", 58.5, 4), "shipped": bench("s", 58.0, 2),
             "teacher": bench("t", 66.5, 2)}
    table = beside_shipped(files)
    assert table.splitlines()[0] == ("| category | candidate SR (%), 4 runs | shipped SR (%), "
                                     "2 runs | teacher SR (%), 2 runs |")
    assert "0.88" not in table and "No candidate / teacher ratio: 4 runs against 2" in table
    files["teacher"] = bench("t4", 67.2, 4)
    assert beside_shipped(files).splitlines()[2].endswith("| 0.87 |")
