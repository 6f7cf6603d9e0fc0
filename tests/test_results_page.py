"""The results page reads its numbers from the committed files (nothing typed by hand)."""

import csv
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))


def write_average(run: Path, cols: list[str], snapshots: int, sr: float) -> None:
    """A run's ``bench_average.csv``: one weight mean of ``snapshots`` snapshots over
    iterations 5-20 (6-18 min), ``sr`` in every column."""
    with open(run / "bench_average.csv", "w", newline="") as f:
        w = csv.DictWriter(f, ["snapshots", "first_iteration", "iteration", "first_minutes",
                               "minutes", *cols])
        w.writeheader()
        w.writerow({"snapshots": snapshots, "first_iteration": 5, "iteration": 20,
                    "first_minutes": 6.0, "minutes": 18.0, **{c: sr for c in cols}})


def test_averaged_snapshots_are_set_beside_the_snapshots_they_span(tmp_path, monkeypatch):
    import results_page

    run = tmp_path / "learn_student" / "h1-unified-s0"
    run.mkdir(parents=True)
    cols = ["d_sr", *(f"sr_{c}" for c in results_page.CATEGORIES)]
    with open(run / "bench.csv", "w", newline="") as f:
        w = csv.DictWriter(f, ["iteration", *cols])
        w.writeheader()
        for it, sr in ((10, 20.0), (20, 40.0), (30, 90.0)):  # the last is outside the span
            w.writerow({"iteration": it, **{c: sr for c in cols}})
    write_average(run, cols, snapshots=3, sr=55.0)
    monkeypatch.setattr(results_page, "RESULTS", tmp_path)
    lines = results_page.averages_section()
    row = next(line for line in lines if "h1-unified-s0" in line)
    assert row.startswith("| `h1-unified-s0` | 3 | 6-18 | 55 (30) |")
    assert row.count("55 (30)") == len(cols)


def test_the_hill_section_sets_each_filmed_student_beside_the_oracle(tmp_path, monkeypatch):
    """``--hill --stage unified`` writes hill/unified/summary.json; the page shows the
    oracle's hill walk and the student's, each with its own film and numbers. Failed
    before: only the oracle's (hill/summary.json) was read."""
    import json

    import results_page

    hill = tmp_path / "hill"
    monkeypatch.setattr(results_page, "HILL", hill)
    base = {"robot": "h1", "level": 1, "seconds": 90.0, "robots": 16, "length_m": 64.0,
            "film_fell": False, "fell_share": 0.25, "reached_share": 0.38}
    (hill / "unified").mkdir(parents=True)
    (hill / "summary.json").write_text(json.dumps(
        {**base, "film_distance_m": 9.1, "mean_distance_m": 40.0}))  # no stage: the oracle
    (hill / "unified" / "summary.json").write_text(json.dumps(
        {**base, "stage": "unified", "film_distance_m": 5.5, "mean_distance_m": 21.5}))
    (hill / "g1" / "unified").mkdir(parents=True)  # G1's pair: hill/g1/, hill/g1/unified/
    (hill / "g1" / "summary.json").write_text(json.dumps(
        {**base, "robot": "g1", "film_distance_m": 7.0, "mean_distance_m": 33.3}))
    (hill / "g1" / "unified" / "summary.json").write_text(json.dumps(
        {**base, "robot": "g1", "stage": "unified", "film_distance_m": 3.0,
         "mean_distance_m": 12.5}))
    page = "\n".join(results_page.hill_section())
    assert page.count("The shipped ") == 4, page  # G1's folder is no H1 student's
    assert "The shipped G1 oracle on `trail=hill`" in page and "33.3 m on average" in page
    assert "--hill --robot g1 --stage unified" in page and "hill/g1/unified/hill.mp4" in page
    assert page.index("H1 unified") < page.index("G1 oracle") < page.index("G1 unified")
    assert "The shipped H1 oracle on `trail=hill`" in page and "40.0 m on average" in page
    assert "The shipped H1 unified student (from depth)" in page and "21.5 m on" in page
    assert "--hill --stage unified" in page and "hill/unified/hill.mp4" in page


def test_an_average_of_a_run_without_benchmarked_snapshots_stands_alone(tmp_path,
                                                                        monkeypatch):
    """A run averaged without ``bench.csv`` (its snapshots never benchmarked, as the
    committed g1-unified-s0-v2lag) gets its row without brackets. Failed before: the page
    stopped with FileNotFoundError, so docs/results.md could not be rewritten."""
    import results_page

    run = tmp_path / "learn_student" / "g1-unified-s0-v2lag"
    run.mkdir(parents=True)
    cols = ["d_sr", *(f"sr_{c}" for c in results_page.CATEGORIES)]
    write_average(run, cols, snapshots=8, sr=52.0)
    monkeypatch.setattr(results_page, "RESULTS", tmp_path)
    row = next(line for line in results_page.averages_section() if "v2lag" in line)
    assert row == "| `g1-unified-s0-v2lag` | 8 | 6-18 | " + " | ".join(["52"] * len(cols)) + " |"


def test_a_milestone_met_at_the_first_evaluation_reads_as_the_start_not_as_zero_frames():
    import results_page

    stones = {"s1": {"frames": 768, "minutes": 0.5}, "s2": {"frames": 691200, "minutes": 24.0},
              "s3": None}
    text = results_page.milestone_text(stones, first_frames=768)
    assert text == ("(s1) met at the first evaluation; (s2) 0.7M frames / 24 min; "
                    "(s3) not reached")


def test_the_sweeps_state_keeps_its_figure_linked_from_the_results_page(tmp_path, monkeypatch):
    """paper_tables.md's links are relative to experiments/results/; copied to docs/ they
    are rewritten to reach the same file."""
    import results_page

    (tmp_path / "paper_tables.md").write_text(
        "# t\n\n## Where the sweep stands\n\n![the jobs](paper_jobs/curves.png)\n")
    monkeypatch.setattr(results_page, "RESULTS", tmp_path)
    lines = results_page.study_section()
    assert f"![the jobs]({results_page.rel(tmp_path / 'paper_jobs' / 'curves.png')})" in lines
    assert "![the jobs](paper_jobs/curves.png)" not in lines
