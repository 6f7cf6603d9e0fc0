"""Which snapshots a campaign's --evaluate scores (experiments/campaign.py)."""

import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
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
