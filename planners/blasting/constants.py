"""Constants of the sand-blasting planner (seed 004, Chapters 3–4).

Seed values name their section; "chosen" values are ours and say why.
"""

from __future__ import annotations

import numpy as np

START_POSE_DEG = (0.0, -75.0, 160.0, 0.0, 30.0, 0.0)  # seed §4.2.4
NOZZLE_LENGTH_M = 0.1  # seed §4.2.4: nozzle 100 mm along the flange z axis
KP = (1.05, 1.10, 1.10)  # seed §4.2.5
FOCI = ((1, 2), (3, 4), (4, -1))  # chosen: upper arm, forearm, wrist + nozzle (params.toml)
MAX_TILT_DEG = 45.0  # seed §3.2.1: nozzle 45–90° to the surface
JUMP_RAD = np.deg2rad(15.0)  # a larger joint change between close way-points is a reconfiguration
SAFETY_M = 0.002  # chosen: a configuration is free only with this much ellipsoid clearance
STEP_RAD = np.deg2rad(2.0)  # largest joint step between way-points of a joint-space move
RETRACT_M = np.array([0.1, 0.2])  # chosen: back-off distances along the nozzle axis for via moves
CLEAR_REL_TOL = 0.05  # chosen: planning bounds may understate a gap by 5 % (the report is exact)
CLEAR_HORIZON_M = 0.25  # clearances beyond this are kept as lower bounds (enough to certify moves)
COVERAGE_TARGET = 0.99  # issue 5: coverage ≥ 99 %
OVERSPRAY_TARGET = 0.005  # issue 5: overspray ≤ 0.5 %
JOINT_PLANNERS = ("rrt", "none")
# chosen: RRT-Connect iterations per blocked move and per plan (deterministic
# budget; an iteration costs ~0.1–0.3 s of clearance evaluations on the
# 2-core machine); a move not found within it leaves its spot unreached
RRT_MAX_ITER = 150
RRT_BUDGET_ITER = 300
