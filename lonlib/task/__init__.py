"""The coupled inverted pendulums task: physics, Gymnasium env, reference controllers, the one
rollout that scores every policy, and behaviour descriptors (numpy only, no torch)."""

from lonlib.task.behaviour import BehaviourDescriptor, as_policy, describe, label, relabel
from lonlib.task.controllers import SwingUpBalanceController
from lonlib.task.env import ENV_ID, CoupledPendulumEnv, register_envs
from lonlib.task.pendulum import CoupledPendulums, EndReason, Policy
from lonlib.task.policy import actor_spec, critic_spec, forward_numpy
from lonlib.task.rollout import (
    Rollout,
    Scores,
    evaluate,
    nominal_offsets,
    perturbed_offsets,
    run_actors,
    run_policy,
    score_actors,
)

__all__ = [
    "BehaviourDescriptor",
    "CoupledPendulumEnv",
    "CoupledPendulums",
    "ENV_ID",
    "EndReason",
    "Policy",
    "Rollout",
    "Scores",
    "SwingUpBalanceController",
    "actor_spec",
    "as_policy",
    "critic_spec",
    "describe",
    "evaluate",
    "forward_numpy",
    "label",
    "nominal_offsets",
    "perturbed_offsets",
    "register_envs",
    "relabel",
    "run_actors",
    "run_policy",
    "score_actors",
]
