"""The benchmark protocol's version (``legoh/eval/protocol.py``): named in every benchmark
file and shipping card; a card, file or sweep of another protocol says so and its figures
are not set beside this protocol's."""

import json
import sys
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from legoh.eval.metrics import METRICS, summarize, write_csv, write_runs_csv
from legoh.eval.protocol import (
    LEGACY,
    PROTOCOL,
    ProtocolMismatch,
    of_card,
    of_csv,
    same_protocol,
    warn_if_other,
)
from legoh.eval.study import gather
from legoh.policies.pretrained import benchmark_protocol, shipped_reference
from tests.conftest import compose_config

ROWS = {"overall": summarize([{m: 1.0 for m in METRICS}])}


def test_this_code_scores_on_v2_and_unnamed_files_are_v1(tmp_path: Path) -> None:
    assert (PROTOCOL, LEGACY) == ("v2", "v1")
    assert of_csv(write_csv(tmp_path / "new.csv", ROWS, "category", PROTOCOL)) == "v2"
    run = {"overall": {m: 1.0 for m in METRICS}}
    assert of_csv(write_runs_csv(tmp_path / "runs.csv", [run], PROTOCOL)) == "v2"
    assert of_csv(write_csv(tmp_path / "old.csv", ROWS, "category")) == "v1"
    assert of_card({"robot": "h1"}) == "v1" and of_card({"protocol": "v2"}) == "v2"


def test_two_protocols_raise_an_error_naming_both() -> None:
    assert same_protocol({"a": "v2", "b": "v2"}) == "v2"
    with pytest.raises(ProtocolMismatch, match="v1: old.csv; v2: new.csv"):
        same_protocol({"new.csv": "v2", "old.csv": "v1"})
    with pytest.warns(UserWarning, match="protocol v1, this code scores on v2"):
        assert warn_if_other("card.json", "v1") is False
    assert warn_if_other("card.json", PROTOCOL) is True


def test_a_study_refuses_a_sweep_of_two_protocols(tmp_path: Path) -> None:
    """Jobs scored on v1 (no protocol column) and v2 are not pooled into one table."""
    for name, version in (("a", None), ("b", PROTOCOL)):
        job = tmp_path / name
        (job / ".hydra").mkdir(parents=True)
        cfg = {"seed": 0, "algo": {"name": name, "total_frames": 10}, "eval": {"runs": 1}}
        (job / ".hydra" / "config.yaml").write_text(OmegaConf.to_yaml(cfg))
        write_csv(job / "benchmark.csv", ROWS, "category", version)
    with pytest.raises(ProtocolMismatch, match="v1: .*a; v2: .*b"):
        gather(tmp_path)


def test_a_card_of_another_protocol_warns_and_sets_nothing_beside(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The main job's reference row of a v1 card (written before the protocol was named) is
    not printed beside a v2 run: a warning names both versions. A v2 card is used."""
    cfg = compose_config()
    rows = {"overall": {m: [1.0, 0.0] for m in METRICS}}
    old = {k: v for k, v in benchmark_protocol(cfg).items() if k != "version"}
    (tmp_path / "h1_oracle.json").write_text(json.dumps(
        {"main_job": {"protocol": old, "rows": rows}}))
    monkeypatch.setattr("legoh.policies.pretrained.PRETRAINED_DIR", tmp_path)
    with pytest.warns(UserWarning, match="protocol v1, this code scores on v2"):
        assert shipped_reference(cfg) is None
    (tmp_path / "h1_oracle.json").write_text(json.dumps(
        {"protocol": PROTOCOL, "main_job": {"protocol": benchmark_protocol(cfg),
                                            "rows": rows}}))
    assert shipped_reference(cfg) == rows


def test_the_shipping_readme_names_each_cards_protocol(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import ship_pretrained

    card = {"robot": "h1", "stage": "oracle", "file": "h1_oracle.pt", "megabytes": 1.0,
            "frames": 10, "iteration": 1, "minutes": 1.0, "commit": "abc", "recipe": "r",
            "run": "x", "benchmark": "table"}
    (tmp_path / "h1_oracle.json").write_text(json.dumps(card))
    (tmp_path / "g1_oracle.json").write_text(json.dumps({**card, "robot": "g1",
                                                         "protocol": PROTOCOL}))
    monkeypatch.setattr(ship_pretrained, "PRETRAINED_DIR", tmp_path)
    ship_pretrained.write_readme()
    text = (tmp_path / "README.md").read_text()
    assert "protocol **v2** (docs" in text
    assert "protocol **v1**: not comparable with v2 figures; re-score with" in text
    assert "--robot h1 --stage oracle --rescore" in text


def test_the_protocol_names_a_trail_geometry_other_than_its_own() -> None:
    """Protocol v2's scenes are the v2 trails; a benchmark on the old geometry says so, and
    its figures are not pooled with v2's."""
    from legoh.eval.protocol import ProtocolMismatch, protocol_of, same_protocol
    from tests.conftest import compose_config

    assert protocol_of(compose_config()) == "v2"
    old = protocol_of(compose_config("trail.geometry=v1"))
    assert old == "v2+geometry-v1"
    with pytest.raises(ProtocolMismatch, match="geometry-v1"):
        same_protocol({"new": "v2", "old trails": old})
