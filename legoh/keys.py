"""TensorDict keys shared by environments, modules, objectives and metrics.

Agreed once here and imported everywhere: a module reads keys and writes keys, nothing
reaches into another's internals. Shapes below are per environment (batch dims first).
"""

# Observations (policy inputs)
PROPRIO = ("obs", "proprio")  # (P,) base ang. vel., gravity, joints, last action, terminus
PROPRIO_HISTORY = ("obs", "proprio_history")  # (10, P) oldest first
SCANDOTS = ("obs", "scandots")  # (132,) heights on a 12 x 11 grid in the yaw frame
PRIVILEGED = ("obs", "privileged")  # (9,) friction, mass/CoM offsets, strength, lin. vel.
GOAL = ("obs", "goal")  # (4,) terminus xy and middle waypoint xy, robot yaw frame, m
COMMAND = ("obs", "command")  # (2,) forward speed m/s and yaw rate rad/s the oracle tracks
DEPTH = ("obs", "depth")  # (T, H, W) depth frames, oldest first, normalised to [-0.5, 0.5]
DEPTH_FRESH = ("obs", "depth_fresh")  # (1,) bool: a new depth frame arrived on this step

# Supervision from the trail (never a deployed input)
EXPERT_GOALS = ("expert", "goals")  # (3, 2) next three expert waypoints, robot yaw frame, m

# Actions and teacher labels
ACTION = "action"
TEACHER_ACTION = ("teacher", "action")
TEACHER_LATENT = ("teacher", "latent")
TEACHER_PRIV_LATENT = ("teacher", "priv_latent")  # (20,) the oracle's privileged latent
# (1,) bool: the teacher's action was executed on this step (DAgger's mixture, train/dagger.py)
TEACHER_ACTED = ("teacher", "acted")

# Student (unified policy and baselines): written by the navigation module, read by the
# locomotion module and the distillation losses
IS_INIT = "is_init"  # (1,) bool: first step of an episode (torchrl's InitTracker)
STUDENT_LATENT = ("student", "latent")  # (32,) z_uni, regresses the oracle's z_tea
# (20,) estimate of the oracle's privileged latent from the proprio history (algo.history_latent)
HISTORY_LATENT = ("student", "history_latent")
NAV_GOAL = ("student", "nav_goal")  # (G,) what locomotion sees: (delta_g0, g1) for LEGO-H
GOAL_CORRECTION = ("student", "goal_correction")  # (2,) delta_g0, robot yaw frame
NEAR_GOALS = ("student", "near_goals")  # (3, 2) predicted g1..g3, robot yaw frame, m
NAV_STATE = ("recurrent", "nav_state")  # (*S) the navigation core's recurrent state
NAV_HELD = ("recurrent", "nav_held")  # (D,) outputs held between depth frames (latent tiling)

# Step results
REWARD = "reward"
DONE, TERMINATED, TRUNCATED = "done", "terminated", "truncated"

# Signals for metrics and logs, per step
INFO = "info"
REACHED = ("info", "reached")  # bool: within the goal radius of the terminus
FELL = ("info", "fell")  # bool: the pose check failed
DIVERGED = ("info", "diverged")  # bool: the simulation diverged this step (env reset in place)
WAYPOINT = ("info", "waypoint")  # int: index of the current expert waypoint
PROGRESS = ("info", "progress")  # float: fraction of the trail's length covered, [0, 1]
EDGE_CONTACTS = ("info", "edge_contacts")  # int: feet in contact on a terrain edge
FOOT_CONTACTS = ("info", "foot_contacts")  # int: feet in contact
UNSAFE_COLLISIONS = ("info", "unsafe_collisions")  # int: non-foot bodies touching the world
LEVEL = ("info", "level")  # int: the env's terrain level
# (3,) float, the same for every env: randomisation strength s and the gate's counts of
# recently ended episodes that were not falls and of all (legoh.envs.mdp.events)
RANDOMIZATION = ("info", "randomization")
CATEGORY = ("info", "category")  # int: index of the env's trail category
TILE = ("info", "tile")  # int: index of the env's tile in the terrain map
EPISODE_STEPS = ("info", "episode_steps")  # int: policy steps of the episode so far
# float: metres of expert path covered toward the terminus this episode (the sum of the
# path progress pn_progress pays; negative when the robot walked away from it)
EPISODE_METRES = ("info", "episode_metres")
WAYPOINT_COUNT = ("info", "waypoint_count")  # int: expert waypoints on the env's trail
BASE_POS = ("info", "base_pos")  # (3,) float: base position, world frame, m
BASE_QUAT = ("info", "base_quat")  # (4,) float: base orientation (w, x, y, z), world frame
REWARD_TERMS = ("info", "reward_terms")  # sub-dict: one (1,) float per reward term
