"""experiments/bench.py: one CLI lists every benchmark, and a results file keeps its history
(no benchmark is run here)."""

import datetime
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))


def test_the_cli_lists_every_benchmark_module() -> None:
    import bench
    from benches import BENCHMARKS

    modules = {p.stem for p in (ROOT / "experiments" / "benches").glob("*.py")}
    assert {module for module, _ in BENCHMARKS.values()} == modules - {"__init__", "common"}
    help_text = bench.parser().format_help()
    for name in BENCHMARKS:
        assert f"  {name} " in help_text, name
    assert not list((ROOT / "experiments").glob("bench_*.py"))  # no script beside the CLI


def test_a_benchmark_takes_the_shared_flags() -> None:
    import bench
    from benches import terrain

    args = bench.bench_parser("terrain", terrain).parse_args(
        ["--tag", "night1", "--note", "idle cores", "--results", "/tmp/x"])
    assert (args.tag, args.note, args.results) == ("night1", "idle cores", Path("/tmp/x"))
    assert args.torch_threads == terrain.TORCH_THREADS


def test_a_results_file_keeps_its_runs_newest_first(tmp_path) -> None:
    from benches import common

    def table(run: dict) -> str:
        return f"| rate |\n|---|\n| {run['results']['rate']} |\n"

    for rate, tag in ((100, "first"), (200, "second")):
        run = common.new_run({"rate": rate}, "2 CPUs", {"sizes": [64]}, tag=tag,
                             note=f"{tag} run")
        common.add_run(tmp_path, "bench_x", run, table, "X speed",
                       lambda r: f"{r['results']['rate']} steps/s")
    runs = json.loads((tmp_path / "bench_x.json").read_text())["runs"]
    today = datetime.date.today().isoformat()
    assert [(r["date"], r["tag"], r["results"]["rate"]) for r in runs] == [
        (today, "second", 200), (today, "first", 100)]
    assert runs[0]["conditions"] == {"sizes": [64]} and runs[0]["machine"] == "2 CPUs"
    md = (tmp_path / "bench_x.md").read_text()
    newest, history = md.split("## History")
    assert "| 200 |" in newest and "| 100 |" not in newest  # the newest run's table
    assert history.strip().splitlines() == [
        f"- {today}, `second`: 200 steps/s. second run",
        f"- {today}, `first`: 100 steps/s. first run"]


def test_runs_of_another_kind_keep_their_own_newest_table(tmp_path) -> None:
    from benches import common

    def table(run: dict) -> str:
        return f"rate {run['results']['rate']}\n"

    for rate, kind in ((1, ""), (2, "quick")):
        common.add_run(tmp_path, "bench_y", common.new_run({"rate": rate}, "m", {}, kind=kind),
                       table, "Y")
    md = (tmp_path / "bench_y.md").read_text()
    assert md.index("rate 1") < md.index("## Newest run (quick)") < md.index("rate 2")
