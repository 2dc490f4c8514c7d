"""The tasks: the coupled inverted pendulums (physics, Gymnasium env, reference controllers, the
one rollout that scores every policy, behaviour descriptors) and any Gymnasium environment
with a continuous action space (:class:`GymnasiumTask`), behind one :class:`Task` interface
(numpy only, no torch)."""

from lonlib.task.behaviour import BehaviourDescriptor, as_policy, describe, label, relabel
from lonlib.task.controllers import SwingUpBalanceController
from lonlib.task.env import ENV_ID, CoupledPendulumEnv, register_envs
from lonlib.task.gymnasium_behaviour import EpisodeTrace, trace_episode
from lonlib.task.gymnasium_task import GymnasiumTask, TaskEnvironmentError
from lonlib.task.interface import PendulumTask, Task, task_of
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
    "EpisodeTrace",
    "GymnasiumTask",
    "PendulumTask",
    "Policy",
    "Rollout",
    "Scores",
    "SwingUpBalanceController",
    "Task",
    "TaskEnvironmentError",
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
    "task_of",
    "trace_episode",
]
