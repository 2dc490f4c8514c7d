"""lonlib: Local Optima Networks of a reinforcement-learning agent's training landscape.

The coupled inverted pendulums task (:mod:`lonlib.pendulum`, :mod:`lonlib.env`), reference
controllers (:mod:`lonlib.controllers`), DDPG as the local search and parameter-level basin
hopping as the global search, and the LON analysis built on what they sample.
"""

import gymnasium as _gym

from lonlib.env import ENV_ID
from lonlib.pendulum import CoupledPendulums, EndReason, PendulumConfig
from lonlib.rollout import Rollout, evaluate

Evaluation = Rollout  # the name ``evaluate`` returned before the one rollout

__version__ = "0.1.0"

if ENV_ID not in _gym.registry:
    _gym.register(id=ENV_ID, entry_point="lonlib.env:CoupledPendulumEnv")

__all__ = [
    "ENV_ID",
    "CoupledPendulums",
    "EndReason",
    "Evaluation",
    "PendulumConfig",
    "__version__",
    "evaluate",
]
