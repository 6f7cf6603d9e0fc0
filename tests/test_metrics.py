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
    trail_completion,
    traverse_rate,
    waypoints_passed,
    write_csv,
    write_markdown,
)

DT = 0.1


def three_robots() -> dict[str, np.ndarray]:
    """T = 5 steps, N = 3 robots (columns): 0 reaches at step 2 (then auto-resets into
    junk, steps 3 and 4, that must be ignored), 1 falls at step 3, 2 times out (truncated
    at step 4)."""
    z = np.zeros((5, 3), dtype=np.int64)
    s = {k: z.copy() for k in ("edge_contacts", "foot_contacts", "unsafe_collisions")}
    s["reached"], s["fell"], s["done"] = (np.zeros((5, 3), bool) for _ in range(3))
    s["progress"] = np.zeros((5, 3))
    # robot 0: success at t=2
    s["progress"][:, 0] = [0.2, 0.5, 0.95, 0.0, 0.1]
    s["reached"][2, 0] = s["done"][2, 0] = True
    s["fell"][4, 0] = True
    s["foot_contacts"][:, 0] = [2, 1, 1, 9, 9]
    s["edge_contacts"][:, 0] = [0, 1, 0, 9, 9]
    s["unsafe_collisions"][:, 0] = [0, 0, 0, 3, 3]
    # robot 1: falls at t=3
    s["progress"][:, 1] = [0.1, 0.3, 0.35, 0.4, 0.0]
    s["fell"][3, 1] = s["done"][3, 1] = True
    s["foot_contacts"][:, 1] = [1, 1, 2, 0, 2]
    s["edge_contacts"][:, 1] = [0, 0, 1, 0, 0]
    s["unsafe_collisions"][:, 1] = [0, 0, 0, 2, 0]
    # robot 2: timeout at t=4; progress went to 0.7 then back to 0.6
    s["progress"][:, 2] = [0.2, 0.4, 0.7, 0.65, 0.6]
    s["done"][4, 2] = True
    s["foot_contacts"][:, 2] = 2
    return s


# Robot 0 walks x from 0 to 4 m past waypoints 0.2 m, 0.5 m and 0.25 m off its line; robot 1
# steps once from (0, 0) to (0, 1), passing 0.29 m from (0.29, 0.5) between the two samples
# (0.58 m from each sample); robot 2 has no waypoint ahead of its spawn.
PATHS = [np.c_[np.linspace(0.0, 4.0, 9), np.zeros(9)], np.array([[0.0, 0.0], [0.0, 1.0]]),
         np.zeros((5, 2))]
AHEAD = [np.array([[1.0, 0.2], [2.0, 0.5], [3.0, -0.25]]), np.array([[0.29, 0.5]]),
         np.zeros((0, 2))]


def test_outcomes_per_robot():
    out = robot_outcomes(dt=DT, paths=PATHS, waypoints=AHEAD, **three_robots())
    np.testing.assert_array_equal(out.success, [True, False, False])
    np.testing.assert_array_equal(out.fall, [False, True, False])
    np.testing.assert_allclose(out.duration, [0.3, 0.4, 0.5])
    np.testing.assert_allclose(out.completion, [2 / 3, 1.0, np.nan])  # a success too
    np.testing.assert_allclose(out.traverse, [1.0, 0.4, 0.6])  # final, not max, progress
    np.testing.assert_allclose(out.violations, [1, 2, 0])  # robot 1: 1 edge + 1 unsafe step
    np.testing.assert_allclose(out.contacts, [4, 5, 10])


def test_metrics_worked_by_hand():
    m = episode_metrics(dt=DT, paths=PATHS, waypoints=AHEAD, **three_robots())
    assert set(m) == set(METRICS)
    assert m["SR"] == pytest.approx(100 / 3)
    assert m["TC"] == pytest.approx(100 * (2 / 3 + 1) / 2)  # robot 2: nothing to count
    assert m["TR"] == pytest.approx(100 * (1 + 0.4 + 0.6) / 3)
    assert m["MEV"] == pytest.approx(100 * 3 / 19)
    assert m["TTF"] == pytest.approx(0.4)  # robot 1's fall only
    assert m["FR"] == pytest.approx(100 / 3)
    assert m["T2R"] == pytest.approx(0.3)
    assert math.isnan(m["DW"])  # no positions given


def test_signals_alone_give_every_metric_but_tc_and_dw():
    """Without paths and waypoints TC is NaN (printed n/a), TR counts from the trail start."""
    m = episode_metrics(dt=DT, **three_robots())
    assert math.isnan(m["TC"]) and math.isnan(m["DW"])
    assert m["TR"] == pytest.approx(100 * 2 / 3) and m["SR"] == pytest.approx(100 / 3)


def test_tr_counts_from_each_robots_spawn():
    """Spawned at progress 0.5, 0.2, 0.5 of the trail: robot 1 ends at 0.4, a quarter of
    its 0.8 of trail; robot 2 at 0.6, a fifth of its 0.5; robot 0 reached (1).

    Failed before with: TR 0.4 and 0.6 (progress from the trail start)."""
    out = robot_outcomes(dt=DT, progress_start=np.array([0.5, 0.2, 0.5]), **three_robots())
    np.testing.assert_allclose(out.traverse, [1.0, 0.25, 0.2])
    # walked back past its spawn: 0, never negative; a spawn at the very end: no division
    np.testing.assert_allclose(traverse_rate(np.array([0.3, 1.0]), np.array([0.5, 1.0]),
                                             np.array([False, False])), [0.0, 0.0])


def test_ttf_is_the_mean_time_of_the_falls_and_fr_their_share():
    """Failed before with: TTF 0.4 = (0.3 + 0.4 + 0.5) / 3 (every episode's duration)."""
    s = three_robots()
    s["fell"][4, 2] = True  # robot 2 falls at its last step (0.5 s) instead of a timeout
    m = episode_metrics(dt=DT, **s)
    assert m["TTF"] == pytest.approx((0.4 + 0.5) / 2) and m["FR"] == pytest.approx(200 / 3)
    s["fell"][:] = False
    none = episode_metrics(dt=DT, **s)
    assert math.isnan(none["TTF"]) and none["FR"] == 0.0  # never fell: TTF n/a, FR scores it


def test_the_hurdle_rma_b_row_is_reachable():
    """Table 8, Hurdle, RMA-B: SR 83.04, T2R 4.22 s, TTF 9.24 s. With 83 of 100 robots
    reaching at 4.22 s the old TTF (every robot's duration) is at most 0.83 * 4.22 + 0.17 *
    30 = 8.6 s; as the mean time of the falls it is 9.24 s when the rest fall at 9.24 s."""
    dt, n = 0.02, 100
    s = {k: np.zeros((1500, n), dtype=bool) for k in ("reached", "fell", "done")}
    s |= {k: np.zeros((1500, n), dtype=np.int64)
          for k in ("edge_contacts", "foot_contacts", "unsafe_collisions")}
    s["progress"] = np.zeros((1500, n))
    s["reached"][210, :83] = s["done"][210, :83] = True  # step 210 ends at 4.22 s
    s["fell"][461, 83:] = s["done"][461, 83:] = True  # step 461 ends at 9.24 s
    m = episode_metrics(dt=dt, **s)
    assert (m["SR"], m["T2R"], m["TTF"], m["FR"]) == pytest.approx((83.0, 4.22, 9.24, 17.0))


def test_waypoints_passed_uses_the_path_between_samples():
    wp = np.array([[0.29, 0.5], [0.31, 0.5], [0.0, 1.2], [5.0, 5.0]])
    np.testing.assert_array_equal(waypoints_passed(PATHS[1], wp, 0.3),
                                  [True, False, True, False])
    assert waypoints_passed(np.zeros((1, 3)), np.array([[0.2, 0.0]]), 0.3).all()  # one sample
    assert waypoints_passed(PATHS[0], np.zeros((0, 2)), 0.3).shape == (0,)
    with pytest.raises(ValueError, match="one path"):
        trail_completion(PATHS, AHEAD[:2])


def signals_of(ends: list[tuple[int, str]], t_len: int = 50) -> dict[str, np.ndarray]:
    """(T, N) signals where robot n's first episode ends at step ends[n][0] by
    ``"reached"``, ``"fell"`` or ``"timeout"``."""
    n = len(ends)
    s = {k: np.zeros((t_len, n), dtype=bool) for k in ("reached", "fell", "done")}
    s |= {k: np.zeros((t_len, n), dtype=np.int64)
          for k in ("edge_contacts", "foot_contacts", "unsafe_collisions")}
    s["progress"] = np.zeros((t_len, n))
    for i, (step, how) in enumerate(ends):
        s["done"][step, i] = True
        if how != "timeout":
            s[how][step, i] = True
    return s


def test_tc_can_fall_below_sr_on_an_open_trail():
    """RandomMix / Forest (Table 8: SR 16.98 vs TC 2.67, 63.29 vs 1.04): two robots reach
    the terminus (10, 0) on a straight line of their own while the expert's evenly spaced
    waypoints bend 0.5-1 m around it; two fall at the start. SR 50 %, TC 0 %."""
    line = np.c_[np.linspace(0.0, 10.0, 41), np.zeros(41)]
    detour = np.array([[2.0, 0.5], [4.0, 1.0], [6.0, 1.0], [8.0, 0.5]])
    paths = [line, line, line[:2], line[:2]]
    m = episode_metrics(dt=DT, paths=paths, waypoints=[detour] * 4,
                        **signals_of([(40, "reached"), (40, "reached"), (1, "fell"),
                                      (1, "fell")]))
    assert m["SR"] == 50.0 and m["TC"] == 0.0 and m["TC"] < m["SR"]


def test_tc_can_rise_above_sr_on_a_crossing_trail():
    """Gap / Hurdle / Ditch (Table 8, Gap, EP-H: SR 18.13 vs TC 32.26): the waypoints sit
    on both lips of the crossing every robot must pass; robots that cross and fall later
    still passed them. SR 0 %, TC 100 %."""
    line = np.c_[np.linspace(0.0, 6.0, 25), np.zeros(25)]
    lips = np.array([[2.0, 0.1], [3.0, -0.1]])
    m = episode_metrics(dt=DT, paths=[line, line], waypoints=[lips, lips],
                        **signals_of([(24, "fell"), (30, "fell")]))
    assert m["SR"] == 0.0 and m["TC"] == 100.0 and m["TC"] > m["SR"]


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
    out = robot_outcomes(dt=DT, distance=np.array([1.0, -0.5, 2.0]), **three_robots())
    np.testing.assert_allclose(out.distance, [1.0, -0.5, 2.0])
    assert aggregate(out)["DW"] == pytest.approx(2.5 / 3)
    assert aggregate(out, np.array([True, True, False]))["DW"] == pytest.approx(0.25)


def test_never_done_counts_as_timeout_at_record_end():
    s = three_robots()
    s["done"][4, 2] = False
    m = robot_outcomes(dt=DT, **s)
    assert m.duration[2] == pytest.approx(0.5) and not m.success[2] and not m.fall[2]


def test_no_success_gives_nan_t2r_and_groups_split():
    s = three_robots()
    per = episode_metrics(dt=DT, groups=["a", "b", "a"], **s)
    assert set(per) == {"a", "b"}
    assert per["a"]["SR"] == pytest.approx(50.0) and per["a"]["T2R"] == pytest.approx(0.3)
    assert math.isnan(per["a"]["TTF"]) and per["a"]["FR"] == 0.0  # no fall in group a
    assert per["b"]["SR"] == 0.0 and math.isnan(per["b"]["T2R"])
    assert per["b"]["TTF"] == pytest.approx(0.4)


def test_shape_mismatch_is_refused():
    s = three_robots()
    s["progress"] = s["progress"][:, :2]
    with pytest.raises(ValueError, match=r"\(T, N\)"):
        episode_metrics(dt=DT, **s)


def test_signals_from_rollout_moves_time_first():
    s = three_robots()
    info = {k: torch.as_tensor(v.T) for k, v in s.items() if k != "done"}  # (N, T)
    td = TensorDict({"next": {"info": info, "done": torch.as_tensor(s["done"].T)[..., None]}},
                    batch_size=[3, 5])
    got = signals_from_rollout(td)
    for k, v in s.items():
        np.testing.assert_array_equal(got[k], v)
    assert episode_metrics(dt=DT, **got)["SR"] == pytest.approx(100 / 3)


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
                        "| T2R (s) ↓ | DW (m) ↑ | FR (%) ↓ |")
    assert "| EP-H | 16.98 ± 0.85 |" in text
    assert lines[-1].endswith("| n/a | 30.99 ± 0.95 | 30.99 ± 0.95 |")
    assert to_markdown(ROWS).count("\n") == 4


def test_csv_table(tmp_path):
    with write_csv(tmp_path / "t.csv", ROWS).open(encoding="utf-8") as f:
        rows = list(csv.reader(f))
    assert rows[0][:3] == ["method", "SR (%) ↑ mean", "SR (%) ↑ std"]
    assert len(rows[0]) == 1 + 2 * len(METRICS) and column_title("MEV") in rows[0][7]
    assert [r[0] for r in rows[1:]] == ["EP-H", "RMA-B"]
    assert rows[0][-4:] == ["DW (m) ↑ mean", "DW (m) ↑ std", "FR (%) ↓ mean", "FR (%) ↓ std"]
    t2r_std = rows[0].index("T2R (s) ↓ std")
    assert float(rows[1][1]) == 16.98 and rows[2][t2r_std] == "nan"
