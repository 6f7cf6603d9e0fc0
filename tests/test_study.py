"""Study tables from sweep folders: per-category rows, and a std over evaluation runs (the
paper's ± is over 5 evaluation runs), pooled exactly over a method's jobs. Job folders are
written by hand here: a benchmark.csv of known per-run values and a .hydra/config.yaml."""

import json
import math

import numpy as np
import pytest
from omegaconf import OmegaConf

from legoh.eval.metrics import METRICS, summarize, write_csv, write_runs_csv
from legoh.eval.study import pool, read_study_csv, study_table


def write_job(folder, algo: str, seed: int, runs: dict[str, list[dict]],
              keep_runs: bool = False, robot: str = "h1") -> None:
    """A finished job: ``runs`` maps a row (category, overall) to its per-run metrics;
    ``keep_runs`` also writes them as the benchmark does (``benchmark_runs.csv``)."""
    (folder / ".hydra").mkdir(parents=True)
    cfg = {"seed": seed, "robot": {"name": robot}, "algo": {"name": algo, "total_frames": 1000},
           "eval": {"runs": len(runs["overall"])}}
    (folder / ".hydra" / "config.yaml").write_text(OmegaConf.to_yaml(cfg))
    rows = {row: summarize(values) for row, values in runs.items()}
    rows["level 0"] = rows["overall"]  # per-level rows are not categories
    write_csv(folder / "benchmark.csv", rows, label="category")
    if keep_runs:
        n = len(runs["overall"])
        write_runs_csv(folder / "benchmark_runs.csv",
                       [{row: values[r] for row, values in runs.items()} for r in range(n)])


def per_run(sr: list[float]) -> list[dict]:
    return [{m: (v if m == "SR" else 1.0) for m in METRICS} for v in sr]


def test_pool_is_the_std_over_all_runs() -> None:
    a, b = [10.0, 20.0, 30.0], [40.0, 60.0]
    mean, std, n = pool([(3, np.mean(a), np.std(a, ddof=1)), (2, np.mean(b), np.std(b, ddof=1))])
    assert n == 5 and mean == pytest.approx(np.mean(a + b))
    assert std == pytest.approx(np.std(a + b, ddof=1))
    assert pool([(1, 5.0, float("nan"))])[:2] == (5.0, 0.0)
    assert math.isnan(pool([(2, float("nan"), float("nan"))])[0])


def test_the_table_has_category_rows_and_a_std_over_evaluation_runs(tmp_path) -> None:
    """Failed before: only the overall row was read, and the std was over the jobs' means
    (seeds): here 2 jobs of 3 runs each give a std over the 6 runs."""
    sweep = tmp_path / "multirun"
    sr = {0: {"forest": [10.0, 20.0, 30.0], "gap": [0.0, 0.0, 30.0]},
          1: {"forest": [40.0, 50.0, 60.0], "gap": [30.0, 30.0, 30.0]}}
    for seed in (0, 1):
        overall = [(f + g) / 2 for f, g in zip(sr[seed]["forest"], sr[seed]["gap"],
                                               strict=True)]
        write_job(sweep / f"unified-seed{seed}", "unified", seed,
                  {"forest": per_run(sr[seed]["forest"]), "gap": per_run(sr[seed]["gap"]),
                   "overall": per_run(overall)})
    paths = study_table(sweep, tmp_path / "table", "plugin_hlm")
    text = paths["markdown"].read_text()
    assert "category forest" in text and "category gap" in text and "level 0" not in text
    forest = sr[0]["forest"] + sr[1]["forest"]
    cell = f"{np.mean(forest):.2f} ± {np.std(forest, ddof=1):.2f}"
    assert cell in text  # 35.00 ± 18.71; over the seeds' means it was 35.00 ± 21.21
    assert "unified 6" in text  # evaluation runs pooled in each row
    csv_rows = paths["csv"].read_text().splitlines()
    assert csv_rows[0].startswith("algo.name,category,")
    # failed before: the jobs' folders were absolute paths of the machine that wrote it
    dirs = [j["dir"] for jobs in json.loads(paths["summary"].read_text())["groups"].values()
            for j in jobs]
    assert sorted(dirs) == ["../multirun/unified-seed0", "../multirun/unified-seed1"]
    assert all((paths["summary"].parent / d / "benchmark.csv").is_file() for d in dirs)
    assert {r.split(",")[1] for r in csv_rows[1:]} == {"overall", "forest", "gap"}


def test_runs_with_a_missing_metric_pool_exactly_from_the_runs_csv(tmp_path) -> None:
    """T2R is NaN in a run without a success. From means and stds alone, job A's two T2R
    values counted as three runs (5.25 ± 1.89); from benchmark_runs.csv the mean and std
    are over the three values there are (5.00 ± 2.00). Failed before: the runs were not
    kept."""
    sweep = tmp_path / "multirun"
    nan = float("nan")
    t2r = {0: [nan, 5.0, 7.0], 1: [3.0]}
    for seed, values in t2r.items():
        write_job(sweep / f"unified-seed{seed}", "unified", seed, {"overall": runs_of(values)},
                  keep_runs=True)
    paths = study_table(sweep, tmp_path / "table", "plugin_hlm")
    text = paths["markdown"].read_text()
    assert "| 5.00 ± 2.00 |" in text
    old = pool([(3, *summarize(runs_of(t2r[0]))["T2R"]), (1, 3.0, 0.0)])
    assert old[:2] == pytest.approx((5.25, 1.893), abs=1e-3)  # the approximation it replaces


def runs_of(values: list[float]) -> list[dict]:
    return [{m: (v if m == "T2R" else 1.0) for m in METRICS} for v in values]


def test_paper_tables_set_a_study_beside_the_paper_and_compare_orderings(tmp_path,
                                                                         monkeypatch) -> None:
    """experiments/paper_tables.py reads a study's table.csv back and orders each metric in
    the paper and in ours: Table 3 has EP-H + HLM better on SR; a study where EP-H wins SR
    clearly disagrees, one within a std ties, and a missing study names its command."""
    import sys
    from pathlib import Path

    from legoh.eval.paper import PAPER_TABLES, ordering
    from legoh.eval.study import read_study_csv

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import paper_tables

    assert ordering((5.0, 1.0), (3.0, 1.0), True) == ">"
    assert ordering((5.0, 1.0), (3.0, 1.0), False) == "<"
    assert ordering((5.0, 3.0), (3.0, 1.0), True) == "="
    assert ordering((float("nan"), 0.0), (3.0, 1.0), True) == "?"
    sweep = tmp_path / "multirun"
    for algo, sr in (("ep_h", [40.0, 42.0, 44.0]), ("ep_h_hlm", [10.0, 12.0, 14.0])):
        write_job(sweep / f"{algo}-seed0", algo, 0, {"overall": per_run(sr)})
    results = tmp_path / "results"
    study_table(sweep, results / "plugin_hlm", "plugin_hlm")
    assert read_study_csv(results / "plugin_hlm" / "table.csv")["overall"]["ep_h"]["SR"] == (
        42.0, 2.0)
    monkeypatch.setattr(paper_tables, "RESULTS", results)
    spec = {t.name: t for t in PAPER_TABLES}
    command = paper_tables.study_command(1000, 3, [0])
    lines, counts = paper_tables.section(spec["table3"], 1000, command)
    sr = next(line for line in lines if line.startswith("| SR"))
    assert sr.endswith("| < | > | no |")  # paper: HLM better; ours: EP-H better
    assert counts["tie"] == 5  # every other metric is 1.0 ± 0.0 for both
    assert "Not this budget" not in "\n".join(lines)
    lines, _ = paper_tables.section(spec["table3"], 5000, command)  # of other frames
    assert "**Not this budget**: the table's jobs trained 1000 frames each, not 5000" in (
        "\n".join(lines))
    lines, counts = paper_tables.section(spec["table1"], 1000, command)
    assert counts == {} and "paper_tables.py --run --recipe v2 --frames 1000 --eval-runs 3 " \
        "--seeds 0`" in "\n".join(lines)



def test_paper_tables_page_keeps_every_table_when_one_is_picked(tmp_path, monkeypatch) -> None:
    """``--tables table4`` picks the studies to run; the page still shows all five tables.
    Failed before: paper_tables.md was rewritten with Table 4 alone."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import paper_tables

    monkeypatch.setattr(paper_tables, "RESULTS", tmp_path)
    monkeypatch.setattr(paper_tables, "JOBS", tmp_path / "paper_jobs")  # the page's figure
    monkeypatch.setattr(sys, "argv", ["paper_tables.py", "--frames", "1000", "--tables",
                                      "table4"])
    paper_tables.main()
    page = (tmp_path / "paper_tables.md").read_text(encoding="utf-8")
    assert [f"## Appendix Table {n}:" in page for n in (1, 2, 3, 4, 8)] == [True] * 5

def test_paper_jobs_run_once_and_each_study_reads_its_own(tmp_path, monkeypatch) -> None:
    """The five paper tables compare 8 distinct jobs a seed (11 before: LEGO-H on H1 ran in
    four studies); one folder of job records serves every study, each table reading only
    the jobs its sweep names; a recorded job is skipped, and one recorded with other frames
    is refused."""
    import sys
    from pathlib import Path

    from legoh.eval.paper import PAPER_TABLES
    from legoh.eval.study import read_study_csv, study_grid

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import paper_tables

    jobs = paper_tables.planned_jobs(PAPER_TABLES, [0])
    assert sorted(jobs) == sorted(
        ["h1-unified-seed0", "h1-unified_ct-seed0", "h1-unified_nohlm-seed0",
         "h1-unified_vae-seed0", "h1-ep_h-seed0", "h1-ep_h_hlm-seed0", "h1-rma_b-seed0",
         "g1-unified-seed0"])
    records = tmp_path / "paper_jobs"
    for name, (robot, algo, seed) in jobs.items():
        sr = 50.0 if robot == "g1" else 10.0 * (1 + sorted(jobs).index(name))
        write_job(records / name, algo, seed, {"overall": per_run([sr, sr + 2.0])},
                  robot=robot)
    study_table(records, tmp_path / "robots", "robots", select=study_grid("robots"))
    robots = read_study_csv(tmp_path / "robots" / "table.csv")["overall"]
    assert set(robots) == {"h1", "g1"} and robots["g1"]["SR"][0] == 51.0
    study_table(records, tmp_path / "t1", "ablation_temporal",
                select=study_grid("ablation_temporal"))
    assert set(read_study_csv(tmp_path / "t1" / "table.csv")["overall"]) == {"unified",
                                                                          "unified_ct"}
    monkeypatch.setattr(paper_tables, "JOBS", records)
    monkeypatch.setattr(paper_tables, "RUNS", tmp_path / "runs")  # nothing may run there
    # records without record.json predate it: recipe v1
    assert paper_tables.run_job("g1-unified-seed0", "g1", "unified", 0, frames=1000,
                                eval_runs=2, overrides=[], recipe="v1") == (
        records / "g1-unified-seed0")
    assert not (tmp_path / "runs").exists()
    with pytest.raises(SystemExit, match="algo.total_frames=1000"):
        paper_tables.run_job("g1-unified-seed0", "g1", "unified", 0, frames=5000,
                             eval_runs=2, overrides=[], recipe="v1")


def test_paper_tables_parallel_jobs_skip_records_and_raise_a_refused_one(tmp_path,
                                                                         monkeypatch):
    """``--parallel 2`` goes through the same per-job rule: recorded jobs are skipped (nothing
    runs), a record of other frames stops the sweep with the job's error, and
    ``--parallel 0`` is refused naming the value."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import paper_tables

    jobs = {"h1-unified-seed0": ("h1", "unified", 0), "g1-unified-seed0": ("g1", "unified", 0)}
    records = tmp_path / "paper_jobs"
    for name, (robot, algo, seed) in jobs.items():
        write_job(records / name, algo, seed, {"overall": per_run([10.0, 12.0])}, robot=robot)
    monkeypatch.setattr(paper_tables, "JOBS", records)
    monkeypatch.setattr(paper_tables, "RUNS", tmp_path / "runs")  # nothing may run there
    paper_tables.run_jobs(jobs, frames=1000, eval_runs=2, overrides=[], parallel=2,
                          recipe="v1")
    assert not (tmp_path / "runs").exists()
    with pytest.raises(SystemExit, match="algo.total_frames=1000"):
        paper_tables.run_jobs(jobs, frames=5000, eval_runs=2, overrides=[], parallel=2,
                              recipe="v1")
    with pytest.raises(SystemExit, match="--parallel 0: valid is >= 1"):
        paper_tables.run_jobs(jobs, frames=1000, eval_runs=2, overrides=[], parallel=0)


def test_a_paper_job_records_its_teacher_and_recipe_and_another_recipe_is_refused(
        tmp_path, monkeypatch) -> None:
    """Each finished job writes record.json (frames, minutes, seed, commit, teacher and its
    hash, protocol, recipe); a recorded job is skipped only under the same recipe: a v1
    record (600k frames, the v1 teachers) must not pass for a v2 sweep's job. Failed
    before: no record.json, and a job of the same frames was skipped whatever its recipe."""
    import hashlib
    import json
    import sys
    from pathlib import Path

    from legoh.checkpoint import save_checkpoint
    from legoh.eval.protocol import PROTOCOL

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import paper_tables

    assert "+experiment=recipe_v1" in paper_tables.job_recipe("v1")
    assert "env.reward_preset=leap" in paper_tables.job_recipe("v2")
    assert all("init=none" in paper_tables.job_recipe(r) for r in ("v1", "v2"))
    records, runs = tmp_path / "paper_jobs", tmp_path / "runs"
    out = runs / "h1-unified-seed0"  # a finished run folder, as run.py leaves it
    write_job(out, "unified", 0, {"overall": per_run([10.0, 12.0])})
    cfg = OmegaConf.load(out / ".hydra" / "config.yaml")
    cfg.algo.num_envs, cfg.algo.steps_per_env = 4, 25  # 100 frames an iteration
    (out / ".hydra" / "config.yaml").write_text(OmegaConf.to_yaml(cfg))
    (out / "train.csv").write_text("iteration,frames_per_s\n1,50\n2,100\n")  # 2 s + 1 s
    teacher = tmp_path / "teacher.pt"
    teacher.write_bytes(b"the teacher's bytes")
    save_checkpoint(out / "unified.pt", {"format": 1, "models": {}, "iteration": 2,
                                         "robot": "h1", "layout": {},
                                         "extra": {"oracle": str(teacher)}})
    monkeypatch.setattr(paper_tables, "JOBS", records)
    monkeypatch.setattr(paper_tables, "RUNS", runs)
    record = paper_tables.run_job("h1-unified-seed0", "h1", "unified", 0, frames=1000,
                                  eval_runs=2, overrides=[], recipe="v2")
    info = json.loads((record / "record.json").read_text())
    assert info["recipe"] == "v2" and info["frames"] == 1000 and info["seed"] == 0
    assert info["minutes"] == round(3 / 60, 2) and info["protocol"] == PROTOCOL
    assert info["teacher_sha"] == hashlib.sha256(b"the teacher's bytes").hexdigest()[:12]
    assert info["commit"]
    assert paper_tables.run_job("h1-unified-seed0", "h1", "unified", 0, frames=1000,
                                eval_runs=2, overrides=[]) == record  # recorded: skipped
    with pytest.raises(SystemExit, match="recipe=v2; this sweep asks .*recipe=v1"):
        paper_tables.run_job("h1-unified-seed0", "h1", "unified", 0, frames=1000,
                             eval_runs=2, overrides=[], recipe="v1")


def test_the_main_comparison_sets_lego_h_beside_each_baseline_per_category(
        tmp_path, monkeypatch) -> None:
    """The main paper's comparison (issue 47): LEGO-H, RMA-H, RMA-B, EP-H on H1, per
    category, the published values beside ours (Table 8's EP-H / RMA-B per category, Table
    4's LEGO-H overall) and our ordering of LEGO-H against each baseline; its jobs join the
    paper tables' (RMA-H the only new one)."""
    import sys
    from pathlib import Path

    from legoh.eval.paper import MAIN, PAPER_TABLES
    from legoh.eval.study import study_table

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import paper_tables

    tables = paper_tables.planned_jobs(PAPER_TABLES, [0, 1])
    both = paper_tables.planned_jobs(PAPER_TABLES, [0, 1], main=True)
    assert sorted(set(both) - set(tables)) == ["h1-rma_h-seed0", "h1-rma_h-seed1"]
    probe = paper_tables.planned_jobs(PAPER_TABLES, [0, 1], True, only=["h1-unified"])
    assert list(probe) == ["h1-unified-seed0", "h1-unified-seed1"]
    with pytest.raises(SystemExit, match="--jobs h1-lego: valid are .*h1-unified"):
        paper_tables.planned_jobs(PAPER_TABLES, [0], only=["h1-lego"])
    monkeypatch.setattr(paper_tables, "RESULTS", tmp_path)
    assert "Not run yet" in "\n".join(paper_tables.main_section("cmd"))
    jobs = tmp_path / "jobs"
    for algo, sr in (("unified", 50.0), ("rma_h", 30.0), ("rma_b", 49.0), ("ep_h", 70.0),
                     ("unified_ct", 99.0)):
        for seed in (0, 1):
            write_job(jobs / f"h1-{algo}-seed{seed}", algo, seed,
                      {"overall": per_run([sr, sr + 2.0]), "gap": per_run([sr, sr])})
    study_table(jobs, tmp_path / MAIN.study, MAIN.study,
                select={**paper_tables.main_grid(), "seed": ["0", "1"]})
    page = "\n".join(paper_tables.main_section("cmd"))
    assert "unified_ct" not in page and "99.00" not in page  # only the four methods
    overall = page.split("**overall**")[1].split("**gap**")[0]
    sr = next(line for line in overall.splitlines() if line.startswith("| SR"))
    assert "68.40 ± 1.34" in sr and sr.endswith("| > / = / < |")  # paper's LEGO-H
    gap = page.split("**gap**")[1]
    sr = next(line for line in gap.splitlines() if line.startswith("| SR"))
    assert "18.13 ± 1.19" in sr and "39.93 ± 1.55" in sr  # Table 8's EP-H and RMA-B on Gap


def test_a_paper_job_killed_at_a_session_end_is_parked_and_resumes_on_a_fresh_clone(
        tmp_path, monkeypatch) -> None:
    """A sweep longer than a session (issue 47: 2 seeds x 9 jobs at >1M frames each): a job
    still training when the session's window (``--minutes``) ends gets SIGTERM, checkpoints
    and is parked in paper_jobs/<job>/unfinished/ (checkpoint, train.csv, config) for
    committing, since a fresh clone lacks multirun/paper/; the next ``--run`` resumes it
    from there, and the finished record replaces it. No job starts past the window.
    Failed before: a killed job's checkpoint stayed in multirun/ and a fresh clone
    restarted the job from scratch."""
    import shutil
    import sys
    import time
    from pathlib import Path

    from legoh.checkpoint import save_checkpoint

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import paper_tables

    records, runs = tmp_path / "paper_jobs", tmp_path / "runs"
    monkeypatch.setattr(paper_tables, "JOBS", records)
    monkeypatch.setattr(paper_tables, "RUNS", runs)
    teacher = tmp_path / "teacher.pt"
    teacher.write_bytes(b"teacher")
    cfg = {"seed": 0, "robot": {"name": "h1"}, "eval": {"runs": 2, "robots": 400},
           "algo": {"name": "unified", "total_frames": 1000, "num_envs": 4,
                    "steps_per_env": 25}}
    calls = []

    def train(rows: str, finished: bool):  # run.py: its run folder as it leaves it
        def run(cmd, log, deadline, evaluating=None):
            calls.append(cmd)
            out = Path(next(c for c in cmd if c.startswith("hydra.run.dir=")).split("=", 1)[1])
            (out / ".hydra").mkdir(parents=True, exist_ok=True)
            (out / ".hydra" / "config.yaml").write_text(OmegaConf.to_yaml(cfg))
            with open(out / "train.csv", "a") as f:
                f.write(rows)
            save_checkpoint(out / "unified.pt", {"format": 1, "models": {}, "iteration": 1,
                                                 "robot": "h1", "layout": {},
                                                 "extra": {"oracle": str(teacher)}})
            if finished:
                write_job(tmp_path / "bench", "unified", 0, {"overall": per_run([40., 42.])})
                shutil.copy(tmp_path / "bench" / "benchmark.csv", out / "benchmark.csv")
            return finished
        return run

    job = ("h1-unified-seed0", "h1", "unified", 0)
    each = {"frames": 1000, "eval_runs": 2, "overrides": [], "eval_robots": 400}
    monkeypatch.setattr(paper_tables, "launch", train("iteration,frames_per_s\n1,50\n", False))
    assert paper_tables.run_job(*job, **each, deadline=time.time() + 60) is None
    parked = records / "h1-unified-seed0" / "unfinished"
    assert {p.name for p in parked.rglob("*") if p.is_file()} == {
        "unified.pt", "train.csv", "config.yaml"}
    assert not (records / "h1-unified-seed0" / "benchmark.csv").exists()
    # the page's progress table reads the parked log: iteration 1 of 100-frame batches
    assert paper_tables.job_state("h1-unified-seed0") == ("parked", 100, 2 / 60, {})
    shutil.rmtree(runs)  # a fresh clone: multirun/ is not committed
    assert paper_tables.run_job(*job, **each, deadline=time.time() - 1) is None  # too late
    assert not runs.exists() and len(calls) == 1
    monkeypatch.setattr(paper_tables, "launch", train("2,100\n", True))
    record = paper_tables.run_job(*job, **each, deadline=time.time() + 60)
    assert f"resume={runs / 'h1-unified-seed0' / 'unified.pt'}" in calls[-1]
    assert "eval.robots=400" in calls[-1] and "algo.total_frames=1000" in calls[-1]
    assert not parked.exists() and (record / "record.json").is_file()
    assert (record / "train.csv").read_text().count("\n") == 3  # the parked rows kept
    state, frames, _, sr = paper_tables.job_state("h1-unified-seed0")
    assert (state, frames, sr["overall"]) == ("recorded", 1000, 41.0)
    progress = "\n".join(paper_tables.progress_section([0], 1000))
    assert "1 of 9 jobs recorded" in progress  # the six tables' and the main comparison's
    assert "| h1-unified-seed0 | recorded | 0.00M | 0 | 41.0 |" in progress
    assert "| h1-rma_h-seed0 | not started |" in progress
    assert "\nLeft: 0.0M frames; at the pace so far" in progress
    assert paper_tables.pace_line([("recorded", 6e6, 200.0, {}), ("parked", 3e6, 100.0, {}),
                                   ("not started", 0, 0.0, {})], int(6e6)) == (
        "Left: 9.0M frames; at the pace so far (30k frames a training minute a job, 2 jobs "
        "at once) ~2 windows of 88 minutes (plus each job's benchmark).")
    command = paper_tables.study_command(1000, 2, [0, 1], "v2", 400)
    progress = "\n".join(paper_tables.progress_section([0], 1000, command=command))
    assert ("goes on with `python experiments/paper_tables.py --run --recipe v2 --frames 1000 "
            "--eval-runs 2 --eval-robots 400 --seeds 0,1 --parallel 2 --minutes 88`") in progress
    with pytest.raises(SystemExit, match="eval.robots=400; this sweep asks .*eval.robots=80:"):
        paper_tables.run_job(*job, **{**each, "eval_robots": 80})
    with pytest.raises(SystemExit, match="--minutes 0: valid is > 0"):
        paper_tables.run_jobs({}, frames=1000, eval_runs=2, overrides=[], minutes=0)
    # --park: the same for a sweep stopped another way; a finished job is not parked
    write_job(runs / "h1-rma_b-seed0", "rma_b", 0, {"overall": per_run([1.0, 2.0])})
    (runs / "h1-rma_b-seed0" / "rma_b.pt").write_bytes(b"finished")
    (runs / "h1-unified-seed0" / "benchmark.csv").unlink()
    assert paper_tables.park(runs, tmp_path / "jobs") == [
        tmp_path / "jobs" / "h1-unified-seed0" / "unfinished"]


def test_a_job_has_trained_all_its_frames_by_its_last_logged_iteration(tmp_path) -> None:
    """``trained_all``: run.py's count (frames // (num_envs x steps_per_env)) against the
    last row of train.csv; no log or config yet: still training.

    Failed before with: AttributeError (there was no such test: a sweep's window SIGTERMed
    a job in its 27-minute benchmark, which killed it, 2026-12-06)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import paper_tables

    assert not paper_tables.trained_all(tmp_path, 1000)
    (tmp_path / ".hydra").mkdir()
    (tmp_path / ".hydra" / "config.yaml").write_text(
        OmegaConf.to_yaml({"algo": {"num_envs": 4, "steps_per_env": 25}}))
    (tmp_path / "train.csv").write_text("iteration,frames_per_s\n1,50\n9,50\n")
    assert not paper_tables.trained_all(tmp_path, 1000)  # 10 iterations of 100 frames
    with open(tmp_path / "train.csv", "a") as f:
        f.write("10,50\n")
    assert paper_tables.trained_all(tmp_path, 1000)
    assert not paper_tables.trained_all(tmp_path, 2000)


def test_a_job_at_the_end_of_its_window_checkpoints_on_sigterm(tmp_path) -> None:
    """``launch``: a job still running at the deadline gets SIGTERM (run.py then finishes
    its iteration and writes its checkpoint) and the sweep is told it did not finish; one
    that ends in time is finished; a failed one raises."""
    import subprocess
    import sys
    import time
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import paper_tables

    mark = tmp_path / "checkpoint"
    job = ("import signal, sys, time\n"
           "def stop(*_):\n"
           f"    open({str(mark)!r}, 'w').write('saved'); sys.exit(143)\n"
           "signal.signal(signal.SIGTERM, stop)\n"
           "print('training', flush=True)\n"
           "time.sleep(30)\n")
    log = tmp_path / "job.log"
    t0 = time.time()
    assert paper_tables.launch([sys.executable, "-c", job], log, time.time() + 3) is False
    assert mark.read_text() == "saved" and time.time() - t0 < 20
    assert "training" in log.read_text()
    assert paper_tables.launch([sys.executable, "-c", "pass"], None, time.time() + 30)
    # past the window while scoring its last checkpoint: it runs to its end, no SIGTERM
    mark.unlink()
    scoring = job.replace("time.sleep(30)", "time.sleep(4)")
    assert paper_tables.launch([sys.executable, "-c", scoring], log, time.time() + 1,
                               lambda: True) is True
    assert not mark.exists()
    with pytest.raises(subprocess.CalledProcessError):
        paper_tables.launch([sys.executable, "-c", "raise SystemExit(3)"], None, None)


def test_reopen_sends_a_recorded_probe_job_back_to_training_at_a_raised_budget(
        tmp_path, monkeypatch) -> None:
    """``--reopen`` (issue 47's budget rule raised the frames after a probe): the record moves
    to paper_budget/<job>-<F>M/ with the run's curve, the run folder's scores move aside and
    its checkpoint is parked, so a fresh clone's ``--run --frames <more>`` resumes the job.
    Every job is checked before any moves. Done by hand twice before (2026-12-06)."""
    import shutil
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import paper_tables

    records, runs, budget = tmp_path / "paper_jobs", tmp_path / "runs", tmp_path / "budget"
    monkeypatch.setattr(paper_tables, "JOBS", records)
    monkeypatch.setattr(paper_tables, "RUNS", runs)
    for folder in (records / "h1-unified-seed0", runs / "h1-unified-seed0",
                   records / "h1-rma_b-seed0"):
        write_job(folder, folder.name.split("-")[1], 0, {"overall": per_run([40.0, 42.0])})
    out = runs / "h1-unified-seed0"
    (out / "unified.pt").write_bytes(b"weights at 1000 frames")
    (out / "train.csv").write_text("iteration,frames_per_s\n1,50\n")
    (out / "learning_curve.png").write_bytes(b"png")
    (out / "benchmark.md").write_text("the table")
    with pytest.raises(SystemExit, match="h1-ep_h-seed0: .* no finished record; valid are "
                                         r"\['h1-rma_b-seed0', 'h1-unified-seed0'\]"):
        paper_tables.reopen(["h1-unified-seed0", "h1-ep_h-seed0"], runs, records, budget)
    with pytest.raises(SystemExit, match="h1-rma_b-seed0: no checkpoint"):
        paper_tables.reopen(["h1-unified-seed0", "h1-rma_b-seed0"], runs, records, budget)
    assert (records / "h1-unified-seed0" / "benchmark.csv").is_file()  # nothing moved
    dest = budget / "h1-unified-seed0-0.00M"
    assert paper_tables.reopen(["h1-unified-seed0"], runs, records, budget) == [dest]
    assert {"benchmark.csv", "benchmark.md", "learning_curve.png"} <= {
        p.name for p in dest.iterdir()}
    assert not (out / "benchmark.csv").exists()
    assert (out / "scored-0.00M" / "benchmark.csv").is_file()
    parked = records / "h1-unified-seed0" / "unfinished"
    assert (parked / "unified.pt").read_bytes() == b"weights at 1000 frames"
    with pytest.raises(SystemExit, match="no finished record"):  # reopened already
        paper_tables.reopen(["h1-unified-seed0"], runs, records, budget)
    shutil.rmtree(runs)  # a fresh clone: the next sweep resumes from the parked checkpoint
    calls = []
    monkeypatch.setattr(paper_tables, "launch",
                        lambda cmd, log, deadline, evaluating=None: calls.append(cmd) or False)
    assert paper_tables.run_job("h1-unified-seed0", "h1", "unified", 0, frames=2000,
                                eval_runs=2, overrides=[]) is None
    assert f"resume={runs / 'h1-unified-seed0' / 'unified.pt'}" in calls[0]
    assert "algo.total_frames=2000" in calls[0]


def test_a_windowed_sweep_keeps_the_tables_of_studies_with_unrecorded_jobs(tmp_path,
                                                                          monkeypatch):
    """A sweep that ends its ``--minutes`` with jobs left writes a study's table only once
    every job of it is recorded. Failed before: the 6M sweep's one finished job replaced
    the complete 600k tables of Tables 1 and 2 with one-row tables, then stopped with
    FileNotFoundError at a study with no finished job."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import paper_tables

    records, results = tmp_path / "paper_jobs", tmp_path / "results"
    write_job(records / "h1-unified-seed0", "unified", 0, {"overall": per_run([60.0, 62.0])})
    kept = results / "ablation_temporal" / "table.csv"
    kept.parent.mkdir(parents=True)
    kept.write_text("the complete table of an earlier budget\n", encoding="utf-8")
    monkeypatch.setattr(paper_tables, "JOBS", records)
    monkeypatch.setattr(paper_tables, "RESULTS", results)
    monkeypatch.setattr(paper_tables, "run_jobs", lambda *a, **k: None)  # the window ended
    monkeypatch.setattr(sys, "argv", ["paper_tables.py", "--run", "--frames", "1000",
                                      "--seeds", "0"])
    paper_tables.main()
    assert kept.read_text(encoding="utf-8") == "the complete table of an earlier budget\n"
    assert sorted(p.name for p in results.iterdir()) == ["ablation_temporal",
                                                          "paper_tables.md"]
    assert paper_tables.unrecorded({"robot.name": ["h1"], "algo.name": ["unified",
                                    "unified_ct"]}, [0]) == ["h1-unified_ct-seed0"]
    write_job(records / "h1-unified_ct-seed0", "unified_ct", 0,
              {"overall": per_run([40.0, 42.0])})
    monkeypatch.setattr(sys, "argv", ["paper_tables.py", "--run", "--frames", "1000",
                                      "--seeds", "0", "--tables", "table1"])
    paper_tables.main()  # Table 1's jobs are all recorded now: its table is written
    table = read_study_csv(kept)["overall"]
    assert set(table) == {"unified", "unified_ct"} and table["unified"]["SR"][0] == 61.0


def test_the_sweeps_figure_draws_recorded_and_parked_jobs_and_skips_unlogged_iterations(
        tmp_path) -> None:
    """``curves_figure`` reads each recorded or parked job's train.csv (frames from its
    config's batch). Its running mean skips NaN (an iteration with no ended episode), where
    counting it as 0 would halve the falls."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import paper_tables

    assert paper_tables.running_mean(np.array([np.nan, 0.5, np.nan, 0.5]), 2).tolist() == [
        0.5, 0.5, 0.5]
    jobs = tmp_path / "jobs"
    for where in (jobs / "h1-unified-seed0", jobs / "h1-unified_ct-seed1" / "unfinished"):
        (where / ".hydra").mkdir(parents=True)
        (where / ".hydra" / "config.yaml").write_text(
            OmegaConf.to_yaml({"algo": {"num_envs": 4, "steps_per_env": 2}}))
        (where / "train.csv").write_text("iteration,fell_frac,episode_metres,reward\n"
                                         "1,,1.0,0.5\n2,0.25,2.0,0.5\n3,0.75,,0.5\n")
    (jobs / "h1-rma_b-seed0").mkdir()  # not started: nothing to draw
    empty = jobs / "h1-rma_h-seed0" / "unfinished"  # parked before its first iteration
    (empty / ".hydra").mkdir(parents=True)
    (empty / ".hydra" / "config.yaml").write_text(
        OmegaConf.to_yaml({"algo": {"num_envs": 4, "steps_per_env": 2}}))
    (empty / "train.csv").write_text("iteration,fell_frac\n")
    assert paper_tables.job_log("h1-rma_h-seed0", jobs) is None
    log = paper_tables.job_log("h1-unified_ct-seed1", jobs)
    assert log["frames"].tolist() == [8.0, 16.0, 24.0] and "distill/loss_action" not in log
    drawn = paper_tables.curves_figure(
        ["h1-unified-seed0", "h1-unified_ct-seed1", "h1-rma_b-seed0"], tmp_path / "c.png",
        jobs, smooth=2)
    assert drawn == ["h1-unified-seed0", "h1-unified_ct-seed1"]
    assert (tmp_path / "c.png").stat().st_size > 10_000
