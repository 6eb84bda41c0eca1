"""Shared constants and enumerations.

Frames and units (used everywhere in the package):

* **World frame**: right-handed, x east, y north, metres; yaw in radians measured
  counter-clockwise from +x.
* **Ego frame (policy interface, paper convention)**: x forward, y to the **right**, metres.
  Conversions live in :mod:`lantern_jax.maths.geometry` (``world_to_ego`` / ``ego_to_world``).
* Time in seconds from the start of an execution; speeds in m/s; accelerations in m/s^2.
"""

from __future__ import annotations

# --- time -------------------------------------------------------------------------------------
DT = 0.05  # s, simulation tick (20 Hz, CARLA leaderboard)
#: s, a recorded rollout (figures, diagnostics) runs to its longest route timeout rounded up to a
#: multiple of this, so the pairs of a suite share a few compiled programs instead of one each
#: (the ticks past an execution's end are frozen and trimmed by every reader)
RECORD_HORIZON_STEP_S = 15.0
#: s, the shortest horizon of a recorded rollout: the built-in suite's longest route timeout
#: (74.5 s) rounded up to RECORD_HORIZON_STEP_S, so that every pair of the built-in suite, and a
#: figure of one pair with a diagnostic of a dozen, run one compiled program
RECORD_MIN_HORIZON_S = 75.0
#: executions, a recorded rollout's batch is padded to a multiple of this (copies of its last
#: execution, dropped from the result) for the same reason: a pair's three executions and a
#: family's twelve share the program of sixteen
RECORD_BATCH_STEP = 16
WAYPOINT_DT = 0.25  # s, spacing of policy waypoints
NUM_WAYPOINTS = 10  # policy output horizon: 10 x 0.25 s = 2.5 s
# m/s, fastest plan a vehicle is asked to drive: a leg of a plan (ego to its first waypoint, or
# one waypoint to the next, 0.25 s apart) longer than MAX_PLAN_SPEED * WAYPOINT_DT (25 m) is a
# controller fault, like a NaN.  Not the paper's (CARLA drives any plan at the controller's
# limits): a project rule, so that a plan in the wrong units or scaled (a model's output x1e4)
# is flagged rather than driven; about nine times the built-in suite's fastest reference speed
# (10.9 m/s), far above any plan a road vehicle follows.
MAX_PLAN_SPEED = 100.0

# --- ego vehicle (Lincoln MKZ 2020, reference/parameters.md) ----------------------------------
EGO_HALF_LENGTH = 2.4508  # m
EGO_HALF_WIDTH = 1.0642  # m
EGO_WHEELBASE = 2.85  # m, physical MKZ wheelbase
EGO_MAX_STEER = 0.3685  # rad, max front-wheel angle (PDM-Lite fit)
EGO_MAX_STEER_RATE = 0.7  # rad/s
EGO_MAX_ACCEL = 3.0  # m/s^2, throttle limit
EGO_MAX_BRAKE = 8.0  # m/s^2, brake limit on dry asphalt (friction 1.0)
GRAVITY = 9.81  # m/s^2
CAMERA_BACK_OFFSET = 1.5  # m, front camera behind the vehicle centre
FRONT_CAMERA_FOV = 110.0  # degrees
SURROUND_FOV = 360.0  # degrees, the six-camera rig (6 x 60 deg, one mounting point)

# --- fixed capacities of a scenario (static shapes shared by every scenario, so they batch) -----
MAX_ACTORS = 16  # A, actor slots
PATH_POINTS = 32  # P, points of an actor's path
MAX_LANES = 16  # L, lane polylines of the road map
LANE_POINTS = 48  # Q, points of a lane polyline
ROUTE_POINTS = 96  # R, points of the ego's route

# --- actor kinds ------------------------------------------------------------------------------
KIND_VEHICLE = 0
KIND_PEDESTRIAN = 1
KIND_STATIC = 2
KIND_NAMES = ("vehicle", "pedestrian", "static")
NUM_ACTOR_KINDS = len(KIND_NAMES)

# --- actor roles ------------------------------------------------------------------------------
ROLE_HAZARD = 0  # the controlled scenario actor (TTC, clearance, warning termination)
ROLE_OCCLUDER = 1  # scenery kept in Route B (parked truck, lead van)
ROLE_CONTEXT = 2  # scenario context actor (Route B stand-in, cross-traffic context)
ROLE_BACKGROUND = 3  # ordinary traffic
ROLE_NAMES = ("hazard", "occluder", "context", "background")
NUM_ROLES = len(ROLE_NAMES)

# --- static occluder kinds (map scenery that blocks camera rays) ------------------------------
OCC_BUILDING = 0  # a building at a junction corner, set back from the kerb
OCC_WALL = 1  # a wall or fence along the sidewalk
OCC_PARKED_VEHICLE = 2  # a parked (or waiting) truck or van
OCCLUDER_KIND_NAMES = ("building", "wall", "parked_vehicle")
NUM_OCCLUDER_KINDS = len(OCCLUDER_KIND_NAMES)

# --- semantic classes of a range-image ray (what its first hit is) ----------------------------
# an actor of kind KIND_* -> that kind; a static occluder of kind OCC_* -> NUM_ACTOR_KINDS + OCC_*
RAY_CLASS_NAMES = KIND_NAMES + OCCLUDER_KIND_NAMES
RAY_CLASS_NONE = -1  # the ray hits nothing within range

# --- actor motion models ----------------------------------------------------------------------
MOTION_SCRIPTED = 0  # path + speed profile + trigger time (closed form in time)
MOTION_IDM = 1  # intelligent-driver-model car following along the actor's path

# --- scripted trigger sources -----------------------------------------------------------------
TRIGGER_CLOCK = 0  # trigger at t = trigger_delay
TRIGGER_EVENT = 1  # trigger at t = t_event + trigger_delay (the protocol's physical event)
TRIGGER_NEVER = 2  # never triggers (Route B stand-ins)

# --- warning overrides (ExecutionConfig.override_*) --------------------------------------------
OVERRIDE_ANCHOR_START = 0  # override window times count from the start of the execution
OVERRIDE_ANCHOR_WARN_POINT = 1  # ... from the ego reaching the warning point (both routes)
OVERRIDE_FRAME_WORLD = 0  # override position fixed in the world frame (grounded every tick)
OVERRIDE_FRAME_EGO = 1  # override position fixed in the ego frame (x forward, y right)

# --- traffic-light states ---------------------------------------------------------------------
LIGHT_GREEN = 0
LIGHT_YELLOW = 1
LIGHT_RED = 2

# --- scenario families (paper order) ----------------------------------------------------------
FAMILIES = ("PE", "VC", "OR", "LWW", "RWW", "RTY")
FAMILY_NAMES = (
    "Pedestrian Emergence",
    "Vehicle Cut-In",
    "Obstacle Reveal",
    "Left-Turn Wrong-Way",
    "Right-Turn Wrong-Way",
    "Right-Turn Yield",
)
PE, VC, OR, LWW, RWW, RTY = range(6)

# --- the two conditions of every Route A execution (result tables' "condition" column) --------
CONDITIONS = ("warning", "no-warning")
WARNING_CONDITION, NO_WARNING_CONDITION = CONDITIONS
#: The blocks of a suite's batch of executions, in order (``sim.engine.Executions``): Route A
#: under each condition, then Route B (the same scene without the hazard).
ROUTE_B = "route-b"
BLOCKS = (*CONDITIONS, ROUTE_B)
EXECUTIONS_PER_PAIR = len(BLOCKS)

# --- the gates of a pair (metrics' ``gate_*`` pass flags; result tables' GATE_COLUMNS) --------
#: Route A gates by telemetry field, in failure-time order (metric ``"gate_" + field``).
ROUTE_A_GATE_FIELDS = ("collision", "route_deviation", "lane", "rule", "block")
ROUTE_A_GATE_NAMES = tuple(f"gate_{field}" for field in ROUTE_A_GATE_FIELDS)
#: All six gates of a pair: Route A's, then Route B's false-brake gate.
GATE_NAMES = (*ROUTE_A_GATE_NAMES, "gate_false_brake")
#: The route-level table's column of each gate, named for what its 1 means (the gate passed):
#: ``no_collision = 1`` is a pair without a collision.
GATE_COLUMNS = {
    "gate_collision": "no_collision",
    "gate_route_deviation": "on_route",
    "gate_lane": "in_lane",
    "gate_rule": "no_red_light",
    "gate_block": "not_blocked",
    "gate_false_brake": "no_false_brake",
}
#: The gate columns of the route-level table, in :data:`GATE_NAMES` order.
GATE_COLUMN_NAMES = tuple(GATE_COLUMNS[g] for g in GATE_NAMES)

# --- weather profiles of the frozen suite -----------------------------------------------------
WEATHERS = ("clear_day", "cloudy_day", "wet_day", "light_rain", "dusk")

# --- the built-in frozen suite ------------------------------------------------------------------
SUITE_ID = "lantern-v3"  # lantern_jax/data/<SUITE_ID>.json

BIG = 1.0e6  # finite stand-in for "infinitely far" distances (keeps gradients finite)
INF_TIME = 1.0e9  # s, stand-in for "not yet happened" times

# --- stress testing: adversary tracks, background traffic, verification horizon -----------------
#: knots per adversary track: a validation bound, not a shape of the worlds (a batch's tracks
#: are as long as its longest one); 256 per-tick knots cover 12.8 s
MAX_KNOTS = 256
#: s, an adversary track's knot length: one tick (per-tick controls) to 2 s
KNOT_S_RANGE = (DT, 2.0)
BACKGROUND_SLOTS = range(2, 7)  # actor slots of a scene's background traffic
MAX_BACKGROUND = len(BACKGROUND_SLOTS)  # background vehicles a scene holds at most
#: s, the longest verified rollout: >= the longest route timeout (20 s + 164 m / 3 m/s); each
#: execution still ends at its own timeout
MAX_VERIFY_S = 90.0

# --- seeds -----------------------------------------------------------------------------------
MAX_SEED = 2**63 - 1  # largest seed anything takes (NumPy's and JAX's generators: 64-bit seeds)

# --- the open-loop dataset's default plan (lantern_jax.apps.dataset.scenes) -------------------
DATASET_SEED = 3272  # default generation seed
# Default size: the paper's release is 3,272 sequences and 236,309 frames (store.PAPER_*; 72 each
# on average); our sequences are shorter (54 frames: see the README, "Dataset"), so matching the
# paper's sequence count gives 178k frames.  380 pairs per family is the round count whose
# default run reaches the paper's frame count (seed 3272: 4,457 sequences, 240,881 frames);
# 280 per family matched its sequence count.
PAIRS_PER_FAMILY = 380  # default: 2280 pairs -> up to 2280 Route A + 2280 Route B sequences
