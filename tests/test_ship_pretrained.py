"""ship_pretrained's clock lookup: an averaged snapshot ships with the minutes of its last
snapshot, not the run's end."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
from ship_pretrained import clock_minutes  # noqa: E402


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
