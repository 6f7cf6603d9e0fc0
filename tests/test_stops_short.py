"""experiments/stops_short.py: which benchmark time-outs ended short of the terminus."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
from stops_short import table_rows, time_outs  # noqa: E402


def robots() -> dict[str, np.ndarray]:
    """Five robots: reached; fell near the terminus; timed out standing 1.2 m from it (short);
    timed out still walking 1.2 m from it; timed out standing 5 m from it."""
    return {"category": np.array(["gap", "gap", "forest", "forest", "forest"]),
            "success": np.array([True, False, False, False, False]),
            "fall": np.array([False, True, False, False, False]),
            "left": np.array([0.8, 1.0, 1.2, 1.2, 5.0]),
            "speed": np.array([0.5, 0.0, 0.03, 0.4, 0.02])}


def test_a_short_time_out_stands_near_the_terminus() -> None:
    timeout, short = time_outs(robots())
    assert timeout.tolist() == [False, False, True, True, True]
    assert short.tolist() == [False, False, True, False, False]


def test_table_rows_per_category_and_overall() -> None:
    rows = table_rows("x", robots())
    assert rows[0] == "| x | gap | 50.0 | 50.0 | 0.0 | 0.0 | - |"
    assert rows[1] == "| x | forest | 0.0 | 0.0 | 100.0 | 33.3 | 1.20 |"
    assert rows[2] == "| x | overall | 20.0 | 20.0 | 60.0 | 20.0 | 1.20 |"
