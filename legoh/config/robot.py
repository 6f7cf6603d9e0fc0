"""Robot config schema (``conf/robot/*.yaml``)."""

from dataclasses import dataclass, field
from enum import Enum


class FeetCollider(Enum):
    """The feet's collision shapes (docs/robots.md, "Feet"). ``source``: the MJCF's own
    colliders (meshes fitted as capsules: H1's three capsules, G1's four spheres), what the
    checkpoints before 2026-12-05 trained on; ``spheres``: four spheres at the corners of the
    sole, the cheapest against height fields; ``box``: one box over the sole."""

    source = "source"
    spheres = "spheres"
    box = "box"


class UpperBody(Enum):
    """What the waist and arms do: hold the default pose, or join the action."""

    hold = "hold"
    active = "active"


@dataclass
class CameraConfig:
    """Egocentric depth camera, fixed to ``body`` (pose in that body's frame). The image it
    gives the policy (size, far plane, rate) is the env's: ``env.depth``."""

    body: str = "torso_link"
    pos: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])  # m, body frame
    pitch_deg: float = 30.0  # downward tilt from horizontal, degrees
    fovy_deg: float = 58.0  # vertical field of view, degrees


@dataclass
class RobotConfig:
    """A humanoid: joint groups, PD gains, default pose, sensors.

    Gains, limits and action scale are matched to joint names by substring (first match wins
    in the order written), as in legged_gym, so one entry covers ``left_knee`` and ``right_knee``.
    """

    name: str = "???"
    mjcf: str | None = None  # path to an MJCF file; None: the Menagerie model from the package
    menagerie_dir: str = "???"  # Menagerie folder inside the assets package (unitree_h1, ...)
    menagerie_file: str = "???"  # MJCF file name inside it
    base_body: str = "pelvis"  # floating base
    leg_joints: list[str] = field(default_factory=list)  # controlled by default, in action order
    upper_joints: list[str] = field(default_factory=list)  # waist and arms
    upper_body: UpperBody = UpperBody.hold  # hold: PD keeps the default pose; active: in the action
    default_pose: dict[str, float] = field(default_factory=dict)  # rad; unnamed joints: 0
    kp: dict[str, float] = field(default_factory=dict)  # N m / rad, by joint-name substring
    kd: dict[str, float] = field(default_factory=dict)  # N m s / rad, by joint-name substring
    torque_limit: dict[str, float] = field(default_factory=dict)  # N m; absent: the MJCF's
    action_scale: float = 0.25  # rad per unit action: target = default + scale * action
    # When set, the per-joint scale is this fraction of torque limit / kp (mjlab's velocity
    # task): unit noise then asks each joint for the same share of its torque, whatever its
    # gains. With kp 800 a uniform 0.25 rad asked an ankle for 200 N m of its 40 (docs/oracle.md).
    effort_action_scale: float | None = None
    nominal_base_height: float = 1.0  # m, pelvis height standing on flat ground
    feet_bodies: list[str] = field(default_factory=list)  # [left, right]
    # what the feet collide with; a checkpoint that did not store it trained on ``source``
    feet_collider: FeetCollider = FeetCollider.spheres
    camera: CameraConfig = field(default_factory=CameraConfig)
    knee_bodies: list[str] = field(default_factory=list)  # shins/knees: collision-term bodies
    hip_joints: list[str] = field(default_factory=list)  # hip yaw/roll: Table 6 "hip position"
    table6_weights: dict[str, float] = field(default_factory=dict)  # this robot's Table 6 column
    # multipliers of the reward preset's weights for this robot (env.rewards still overrides);
    # G1: the velocity kernels x 2 (docs/oracle.md, "G1")
    reward_scales: dict[str, float] = field(default_factory=dict)
    render_meshes: bool = False  # keep visual meshes (rendering); training strips them
