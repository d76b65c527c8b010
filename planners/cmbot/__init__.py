"""CMBOT planning (seed 002): biped climbing gait along a guardrail and
7-DoF redundant-arm maintenance motions with obstacle avoidance, each checked
by a fine-step simulation gate before approval.

Entry points: :func:`plan_climb` → :class:`ClimbPlan`,
:func:`plan_manipulation` → :class:`ManipulationPlan`.  Both take the robot
model from ``robots.load_robot("cmbot")``.
"""

from planners.cmbot.avoidance import AvoidanceParams
from planners.cmbot.climb import SEED_CLIMB_GOAL_X, SEED_CLIMB_START_X, ClimbPlan, plan_climb
from planners.cmbot.experiment import ExperimentParams, Section4Trajectory
from planners.cmbot.gait import GaitParams
from planners.cmbot.guardrail import Guardrail, GuardrailParams, make_guardrail, seed_guardrail
from planners.cmbot.manipulation import SEED_WORK_REAR_X, ManipulationPlan, plan_manipulation
from planners.cmbot.simulate import GateReport

__all__ = [
    "SEED_CLIMB_GOAL_X",
    "SEED_CLIMB_START_X",
    "SEED_WORK_REAR_X",
    "AvoidanceParams",
    "ClimbPlan",
    "ExperimentParams",
    "GaitParams",
    "GateReport",
    "Guardrail",
    "GuardrailParams",
    "ManipulationPlan",
    "Section4Trajectory",
    "make_guardrail",
    "plan_climb",
    "plan_manipulation",
    "seed_guardrail",
]
