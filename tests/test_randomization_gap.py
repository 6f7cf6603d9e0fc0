"""randomization_gap: the student / teacher ratio with randomisation off and on, read from
the four evaluations' benchmark.csv."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
from randomization_gap import ROWS, folder, plot, table  # noqa: E402


def test_the_table_sets_each_ratio_beside_its_teacher(tmp_path):
    srs = {("oracle", False): 90.0, ("unified", False): 85.5, ("oracle", True): 80.0,
           ("unified", True): 60.0}
    for (algo, randomization), sr in srs.items():
        path = folder(tmp_path, algo, randomization)
        path.mkdir()
        lines = ["category,SR (%) ↑ mean,SR (%) ↑ std,FR (%) ↓ mean,FR (%) ↓ std,protocol"]
        lines += [f"{row},{sr},2.0,{100 - sr},1.0,v2" for row in ROWS]
        (path / "benchmark.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    got = table(tmp_path)
    assert got["unified", True]["gap"] == (60.0, 2.0, 40.0)
    overall = (tmp_path / "table.md").read_text().splitlines()[-1]
    assert overall.startswith("| overall | 90.0 ± 2.0 | 85.5 ± 2.0 | 0.95 | 80.0 ± 2.0 | "
                              "60.0 ± 2.0 | 0.75 |")
    assert overall.endswith("| 10.0 / 14.5 | 20.0 / 40.0 |")
    assert plot(got, tmp_path, "g1").stat().st_size > 0
