"""Entry points dispatch on ``algo.stage``, never on ``algo.name``: a variant may take any
name (issue 19: ``oracle_lean`` was trained as a student)."""

from pathlib import Path

import pytest

from legoh import app
from legoh.config.algo import Stage
from tests.conftest import CONF_DIR, compose_config


class Reached(Exception):
    """Raised by a stand-in trainer: the stage the dispatch chose."""


def _stand_in(stage: Stage):
    def train(*args, **kwargs):
        raise Reached(stage)
    return train


@pytest.fixture
def trainers(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("legoh.train.oracle.train_oracle", _stand_in(Stage.oracle))
    monkeypatch.setattr("legoh.train.unified.train_student", _stand_in(Stage.student))


@pytest.mark.parametrize(("overrides", "stage"), [
    (["algo=oracle", "algo.name=oracle_lean"], Stage.oracle),
    (["algo=unified", "algo.name=oracle_like_name"], Stage.student),
    (["algo=oracle"], Stage.oracle),
    (["algo=ep_h"], Stage.student),
])
def test_training_goes_by_the_declared_stage(overrides, stage, trainers, tmp_path: Path
                                             ) -> None:
    with pytest.raises(Reached) as reached:
        app.train_and_evaluate(compose_config(*overrides), tmp_path)
    assert reached.value.args[0] == stage


def test_export_refuses_an_oracle_of_any_name(tmp_path: Path) -> None:
    cfg = compose_config("algo=oracle", "algo.name=oracle_lean", "checkpoint=x.pt")
    with pytest.raises(ValueError, match="deploys a depth student"):
        app.export(cfg, tmp_path)


def test_every_algo_option_declares_its_stage() -> None:
    for path in sorted((Path(CONF_DIR) / "algo").glob("*.yaml")):
        cfg = compose_config(f"algo={path.stem}")
        want = Stage.oracle if path.stem == "oracle" else Stage.student
        assert cfg.algo.stage == want, path.name
