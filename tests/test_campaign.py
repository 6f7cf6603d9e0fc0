"""Which snapshots a campaign's --evaluate scores (experiments/campaign.py)."""

import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
from campaign import snapshots_to_score  # noqa: E402


def test_snapshots_fill_gaps_before_the_newest_scored_one(tmp_path) -> None:
    # Fault: only snapshots after the last scored one were picked, so once the newest was
    # scored the earlier 90 minutes could never be benchmarked
    (tmp_path / "snapshots").mkdir()
    for it, minutes in [(10, 6.0), (20, 12.0), (30, 18.0), (40, 24.0), (50, 30.0)]:
        torch.save({"iteration": it, "minutes": minutes},
                   tmp_path / "snapshots" / f"it{it:06d}.pt")
    rows = [{"iteration": 50, "minutes": 30.0}]  # the newest is already scored
    picked = [s["iteration"] for _, s in snapshots_to_score(tmp_path, rows, 10.0)]
    assert picked == [10, 30]  # 12 and 24 lie within 10 minutes of a scored one
    assert [s["iteration"] for _, s in snapshots_to_score(tmp_path, [], 10.0)] == [10, 30, 50]


def test_a_comparison_of_scored_runs_sets_their_benchmarks_side_by_side(tmp_path) -> None:
    """compare_runs adds the benchmark (RandomMix 0-2 and per category, the teacher's in
    brackets) when every run has a bench.csv: the camera A/B (pitch 55 vs 30) was read
    from walk tests alone before, which both cameras pass."""
    from campaign import compare_runs

    root = ROOT / "experiments/results/learn_student"
    runs = [root / "h1-unified-s0-pitch55", root / "h1-unified-s0-pitch30"]
    stem = compare_runs(runs, tmp_path / "ab", "s1", "a walk test")
    table = stem.with_suffix(".md").read_text()
    assert "| run | minutes | frames (M) | RandomMix 0-2 | randommix | ditch |" in table
    assert "| h1-unified-s0-pitch55 | 36.0 | 1.31 | 62 (71) |" in table
    assert stem.with_suffix(".png").stat().st_size > 20_000


def test_the_training_curve_breaks_where_a_session_lost_its_rows(tmp_path) -> None:
    """train.csv of learn_hike/g1-s0-v2 lacks iterations 276-1220; the curve breaks there
    (a NaN in the line's x) instead of drawing a straight line across 12M frames. Failed
    before: the line ran on without a gap."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from campaign import plot_training

    iterations = [*range(1, 41), *range(100, 141)]
    with open(tmp_path / "train.csv", "w") as f:
        f.write("iteration,level/gap,fell/gap,level_mean\n")
        f.writelines(f"{i},{i / 100},0.5,{i / 100}\n" for i in iterations)
    fig, axes = plt.subplots(1, 2)
    plot_training(axes, tmp_path, 1000.0, ["gap"])
    x = axes[0].lines[0].get_xdata()
    plt.close(fig)
    assert len(x) == len(iterations) + 1 and np.isnan(x[40])
    assert np.isfinite(np.delete(x, 40)).all() and x[41] == 0.1  # 100 x 1000 frames


def test_a_resumed_campaign_writes_its_clock_back_with_integer_iterations(tmp_path) -> None:
    """read_rows keeps an integer cell an int, so a resumed run's rewrite of clock.csv keeps
    ``2989``. Failed before: every cell came back a float and the file said ``2989.0``."""
    from campaign import read_rows, write_rows

    path = tmp_path / "clock.csv"
    path.write_text("iteration,minutes\n0,0.0\n2989,85.0195\n")
    rows = read_rows(path)
    assert rows[1] == {"iteration": 2989, "minutes": 85.0195}
    write_rows(path, rows)
    assert path.read_text().splitlines() == ["iteration,minutes", "0,0.0", "2989,85.0195"]
