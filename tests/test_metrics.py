"""Benchmark metrics on hand-built episodes with answers worked by hand."""

import csv
import math

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from legoh.eval.metrics import (
    METRICS,
    aggregate,
    column_title,
    distance_walked,
    episode_metrics,
    robot_outcomes,
    signals_from_rollout,
    summarize,
    to_markdown,
    write_csv,
    write_markdown,
)

DT = 0.1
COUNT = np.array([4, 4, 4])


def three_robots() -> dict[str, np.ndarray]:
    """T = 5 steps, N = 3 robots (columns): 0 reaches at step 2 (then auto-resets into
    junk that must be ignored), 1 falls at step 3, 2 times out (truncated at step 4)."""
    z = np.zeros((5, 3), dtype=np.int64)
    s = {k: z.copy() for k in ("waypoint", "edge_contacts", "foot_contacts",
                               "unsafe_collisions")}
    s["reached"], s["fell"], s["done"] = (np.zeros((5, 3), bool) for _ in range(3))
    s["progress"] = np.zeros((5, 3))
    # robot 0: success at t=2
    s["waypoint"][:, 0] = [0, 1, 2, 3, 3]  # the post-reset steps 3, 4 are junk
    s["progress"][:, 0] = [0.2, 0.5, 0.95, 0.0, 0.1]
    s["reached"][2, 0] = s["done"][2, 0] = True
    s["fell"][4, 0] = True
    s["foot_contacts"][:, 0] = [2, 1, 1, 9, 9]
    s["edge_contacts"][:, 0] = [0, 1, 0, 9, 9]
    s["unsafe_collisions"][:, 0] = [0, 0, 0, 3, 3]
    # robot 1: falls at t=3
    s["waypoint"][:, 1] = [0, 1, 1, 1, 0]
    s["progress"][:, 1] = [0.1, 0.3, 0.35, 0.4, 0.0]
    s["fell"][3, 1] = s["done"][3, 1] = True
    s["foot_contacts"][:, 1] = [1, 1, 2, 0, 2]
    s["edge_contacts"][:, 1] = [0, 0, 1, 0, 0]
    s["unsafe_collisions"][:, 1] = [0, 0, 0, 2, 0]
    # robot 2: timeout at t=4; progress went to 0.7 then back to 0.6
    s["waypoint"][:, 2] = [0, 1, 2, 2, 2]
    s["progress"][:, 2] = [0.2, 0.4, 0.7, 0.65, 0.6]
    s["done"][4, 2] = True
    s["foot_contacts"][:, 2] = 2
    return s


def test_outcomes_per_robot():
    out = robot_outcomes(waypoint_count=COUNT, dt=DT, **three_robots())
    np.testing.assert_array_equal(out.success, [True, False, False])
    np.testing.assert_array_equal(out.fall, [False, True, False])
    np.testing.assert_allclose(out.duration, [0.3, 0.4, 0.5])
    np.testing.assert_allclose(out.completion, [1.0, 0.25, 0.5])
    np.testing.assert_allclose(out.traverse, [1.0, 0.4, 0.6])  # final, not max, progress
    np.testing.assert_allclose(out.violations, [1, 2, 0])  # robot 1: 1 edge + 1 unsafe step
    np.testing.assert_allclose(out.contacts, [4, 5, 10])


def test_metrics_worked_by_hand():
    m = episode_metrics(waypoint_count=COUNT, dt=DT, **three_robots())
    assert set(m) == set(METRICS)
    assert m["SR"] == pytest.approx(100 / 3)
    assert m["TC"] == pytest.approx(100 * (1 + 0.25 + 0.5) / 3)
    assert m["TR"] == pytest.approx(100 * (1 + 0.4 + 0.6) / 3)
    assert m["MEV"] == pytest.approx(100 * 3 / 19)
    assert m["TTF"] == pytest.approx(0.4)  # (0.3 + 0.4 + 0.5) / 3
    assert m["T2R"] == pytest.approx(0.3)
    assert math.isnan(m["DW"])  # the signals alone carry no positions


def test_distance_walked_by_hand():
    """Terminus at (10, 0): from (0, 0) to (3, 4) is 10 -> sqrt(49 + 16) closer; standing
    still is 0; walking from (2, 0) back to (-1, 0) is 8 -> 11, i.e. -3."""
    start = np.array([[0.0, 0.0], [5.0, 5.0], [2.0, 0.0]])
    end = np.array([[3.0, 4.0], [5.0, 5.0], [-1.0, 0.0]])
    got = distance_walked(start, end, np.array([[10.0, 0.0]] * 3))
    np.testing.assert_allclose(got, [10.0 - math.sqrt(65.0), 0.0, -3.0])
    # (N, 3) positions: z (height) is ignored
    z = distance_walked(np.c_[start, [0.0, 1.0, 2.0]], np.c_[end, [9.0, 0.0, 0.0]],
                        np.array([[10.0, 0.0, 5.0]] * 3))
    np.testing.assert_allclose(z, got)


def test_dw_is_the_mean_over_selected_robots():
    out = robot_outcomes(waypoint_count=COUNT, dt=DT, distance=np.array([1.0, -0.5, 2.0]),
                         **three_robots())
    np.testing.assert_allclose(out.distance, [1.0, -0.5, 2.0])
    assert aggregate(out)["DW"] == pytest.approx(2.5 / 3)
    assert aggregate(out, np.array([True, True, False]))["DW"] == pytest.approx(0.25)


def test_never_done_counts_as_timeout_at_record_end():
    s = three_robots()
    s["done"][4, 2] = False
    m = robot_outcomes(waypoint_count=4, dt=DT, **s)
    assert m.duration[2] == pytest.approx(0.5) and not m.success[2] and not m.fall[2]


def test_no_success_gives_nan_t2r_and_groups_split():
    s = three_robots()
    per = episode_metrics(waypoint_count=COUNT, dt=DT, groups=["a", "b", "a"], **s)
    assert set(per) == {"a", "b"}
    assert per["a"]["SR"] == pytest.approx(50.0) and per["a"]["T2R"] == pytest.approx(0.3)
    assert per["b"]["SR"] == 0.0 and math.isnan(per["b"]["T2R"])
    assert per["b"]["TTF"] == pytest.approx(0.4)


def test_shape_mismatch_is_refused():
    s = three_robots()
    s["progress"] = s["progress"][:, :2]
    with pytest.raises(ValueError, match=r"\(T, N\)"):
        episode_metrics(waypoint_count=COUNT, dt=DT, **s)


def test_signals_from_rollout_moves_time_first():
    s = three_robots()
    info = {k: torch.as_tensor(v.T) for k, v in s.items() if k != "done"}  # (N, T)
    td = TensorDict({"next": {"info": info, "done": torch.as_tensor(s["done"].T)[..., None]}},
                    batch_size=[3, 5])
    got = signals_from_rollout(td)
    for k, v in s.items():
        np.testing.assert_array_equal(got[k], v)
    assert episode_metrics(waypoint_count=COUNT, dt=DT, **got)["SR"] == pytest.approx(100 / 3)


def test_summarize_mean_and_sample_std():
    runs = [dict.fromkeys(METRICS, 1.0), dict.fromkeys(METRICS, 3.0)]
    runs[1]["T2R"] = float("nan")
    stats = summarize(runs)
    assert stats["SR"] == pytest.approx((2.0, math.sqrt(2.0)))
    assert stats["T2R"] == (1.0, 0.0)  # NaN left out; one value -> std 0


ROWS = {"EP-H": {m: (16.98, 0.85) for m in METRICS},
        "RMA-B": {**{m: (30.99, 0.95) for m in METRICS}, "T2R": (float("nan"),) * 2}}


def test_markdown_table(tmp_path):
    text = write_markdown(tmp_path / "t.md", ROWS, title="RandomMix").read_text()
    lines = text.splitlines()
    assert lines[0] == "**RandomMix**"
    assert lines[2] == ("| Method | SR (%) ↑ | TC (%) ↑ | TR (%) ↑ | MEV (%) ↓ | TTF (s) ↑ "
                        "| T2R (s) ↓ | DW (m) ↑ |")
    assert "| EP-H | 16.98 ± 0.85 |" in text and lines[-1].endswith("| n/a | 30.99 ± 0.95 |")
    assert to_markdown(ROWS).count("\n") == 4


def test_csv_table(tmp_path):
    with write_csv(tmp_path / "t.csv", ROWS).open(encoding="utf-8") as f:
        rows = list(csv.reader(f))
    assert rows[0][:3] == ["method", "SR (%) ↑ mean", "SR (%) ↑ std"]
    assert len(rows[0]) == 1 + 2 * len(METRICS) and column_title("MEV") in rows[0][7]
    assert [r[0] for r in rows[1:]] == ["EP-H", "RMA-B"]
    assert rows[0][-2:] == ["DW (m) ↑ mean", "DW (m) ↑ std"]
    t2r_std = rows[0].index("T2R (s) ↓ std")
    assert float(rows[1][1]) == 16.98 and rows[2][t2r_std] == "nan"
