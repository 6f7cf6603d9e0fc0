"""A policy acts on the feet it trained on: committed checkpoints (trained before
``robot.feet_collider`` existed) evaluate, film and resume on the MJCF's own colliders,
while new training takes the config's default (``legoh.policies.embodiment``)."""

from __future__ import annotations

import mujoco
import pytest
import torch

from legoh.checkpoint import make_payload, save_checkpoint
from legoh.config.robot import FeetCollider
from legoh.eval.benchmark import make_eval_env
from legoh.eval.cli import for_checkpoint
from legoh.policies.embodiment import checkpoint_feet, with_checkpoint_body
from legoh.train.teacher import run_body
from tests.conftest import compose_config


def foot_geom_types(env) -> list[int]:
    model = env.scene.model
    foot = model.body(env.robot.feet_bodies[0]).id
    return sorted(model.geom_type[(model.geom_bodyid == foot) & (model.geom_contype > 0)])


@pytest.mark.parametrize(("robot", "algo", "feet"), [
    ("h1", "oracle", FeetCollider.spheres),  # the recipe-v2 oracles (shipped 2026-12-06)
    ("g1", "oracle", FeetCollider.spheres),
    ("h1", "unified", FeetCollider.spheres),  # the v2 oracles' students (shipped 2026-12-06)
    ("g1", "unified", FeetCollider.spheres)])
def test_committed_checkpoints_evaluate_on_their_own_feet(robot: str, algo: str,
                                                          feet: FeetCollider) -> None:
    cfg = compose_config(f"robot={robot}", f"algo={algo}", "trail=flat", "trail.variants=1",
                         "trail.levels=1", "eval.robots=1", "eval.levels=[0]")
    assert cfg.robot.feet_collider == FeetCollider.spheres  # what new training uses
    own, path = for_checkpoint(cfg, "pretrained")
    assert checkpoint_feet(path) == feet.value
    assert own.robot.feet_collider == feet
    env = make_eval_env(own)
    if robot == "h1":  # the MJCF's three capsules, or the four spheres
        assert foot_geom_types(env) == (
            [mujoco.mjtGeom.mjGEOM_CAPSULE] * 3 if feet == FeetCollider.source
            else [mujoco.mjtGeom.mjGEOM_SPHERE] * 4)
    env.close()


def test_a_checkpoint_keeps_its_feet_through_resume_and_distillation(tmp_path) -> None:
    """A checkpoint that stored its feet gives them back; a resumed oracle run and a
    student distilled from a teacher take the checkpoint's feet, a new oracle run the
    config's."""
    path = save_checkpoint(tmp_path / "oracle.pt", make_payload(
        models={"actor": torch.nn.Linear(2, 2)}, iteration=1, robot="h1", layout={},
        config={"robot": {"feet_collider": "box"}}))
    cfg = compose_config("robot=h1")
    assert with_checkpoint_body(cfg, path).robot.feet_collider == FeetCollider.box
    assert run_body(cfg, str(path)).robot.feet_collider == FeetCollider.box
    assert run_body(cfg, None).robot.feet_collider == FeetCollider.spheres
    student = compose_config("robot=h1", "algo=unified", f"algo.oracle_checkpoint={path}")
    assert run_body(student, None).robot.feet_collider == FeetCollider.box
    assert cfg.robot.feet_collider == FeetCollider.spheres  # the caller's config untouched


def test_an_unknown_feet_collider_is_refused_naming_the_choices() -> None:
    with pytest.raises(Exception, match="feet_collider") as err:
        compose_config("robot.feet_collider=cylinders")
    said = f"{err.value} {err.value.__cause__}"  # Hydra prints the cause beneath
    assert all(k in said for k in ("cylinders", "source", "spheres", "box"))
