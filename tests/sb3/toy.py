"""A toy Gymnasium task for the SB3 tests: two actions with asymmetric bounds and observations
with a finite, a shifted and an infinite range, so that every part of the conversion shows."""

import gymnasium
import numpy as np

from lonlib.config import DDPGConfig
from lonlib.config.task import GymnasiumTaskConfig
from lonlib.task.gymnasium_task import GymnasiumTask

TOY_ID = "lonlib-tests/Toy-v0"


class ToyEnv(gymnasium.Env):
    """Observations in [-2, 2] x [0, 10] x R, actions in [-2, 3] x [0, 5]; the reward pulls
    the actions towards the middle of their ranges."""

    def __init__(self):
        self.observation_space = gymnasium.spaces.Box(
            np.array([-2.0, 0.0, -np.inf]), np.array([2.0, 10.0, np.inf]), dtype=np.float64
        )
        self.action_space = gymnasium.spaces.Box(
            np.array([-2.0, 0.0], dtype=np.float32), np.array([3.0, 5.0], dtype=np.float32)
        )
        self.state = np.zeros(3)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.state = self.np_random.uniform([-2.0, 0.0, -3.0], [2.0, 10.0, 3.0])
        return self.state.copy(), {}

    def step(self, action):
        action = np.asarray(action, dtype=np.float64)
        self.state = np.clip(self.state + 0.1 * np.r_[action, action.sum()], -50, 50)
        reward = -float(np.sum((action - np.array([0.5, 2.5])) ** 2))
        return self.state.copy(), reward, False, False, {}


if TOY_ID not in gymnasium.registry:
    gymnasium.register(TOY_ID, entry_point=ToyEnv, max_episode_steps=20)


def toy_task(search: str) -> GymnasiumTask:
    """The toy environment as a task searched by ``search``."""
    return GymnasiumTask(
        GymnasiumTaskConfig(gymnasium=TOY_ID, fitness_range=(-200.0, 0.0), search=search)
    )


def pendulum_task(search: str, episode_steps: int = 50) -> GymnasiumTask:
    """Pendulum-v1 with short episodes, searched by ``search``."""
    return GymnasiumTask(
        GymnasiumTaskConfig(
            gymnasium="Pendulum-v1",
            fitness_range=(-800.0, 0.0),
            episode_steps=episode_steps,
            search=search,
        )
    )


def tiny_hp(**overrides) -> DDPGConfig:
    """Small, fast SB3 searches: batches of 16 from 500 transitions, 50 warm-up steps."""
    values = {
        "batch_size": 16,
        "buffer_size": 500,
        "warmup_steps": 50,
        "max_steps": 200,
        "min_steps": 0,
        "patience_steps": 10_000,
    }
    return DDPGConfig(**{**values, **overrides})
