"""lonlib: Local Optima Networks of a reinforcement-learning agent's training landscape.

The coupled inverted pendulums task (:mod:`lonlib.task.pendulum`, :mod:`lonlib.task.env`), reference
controllers (:mod:`lonlib.task.controllers`), DDPG as the local search and parameter-level basin
hopping as the global search, and the LON analysis built on what they sample.
"""

# First, before anything here imports torch: torch's AVX2 CPU kernels on every x86-64 machine
# (lonlib.util.cpu_kernels: the same trials bit for bit on any CPU with AVX2).
from lonlib.util.cpu_kernels import pin_torch_cpu_kernels as _pin

_pin()

from lonlib.config import PendulumConfig  # noqa: E402
from lonlib.task.env import ENV_ID, register_envs  # noqa: E402
from lonlib.task.pendulum import CoupledPendulums, EndReason  # noqa: E402
from lonlib.task.rollout import evaluate  # noqa: E402

__version__ = "0.1.0"

register_envs()

__all__ = [
    "ENV_ID",
    "CoupledPendulums",
    "EndReason",
    "PendulumConfig",
    "__version__",
    "evaluate",
]
