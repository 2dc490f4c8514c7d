"""lonlib's DDPG on a Gymnasium task (``lonlib.ddpg.gymnasium_search``): it learns, it keeps
the slot trainer's rules of what it returns, and it is a deterministic function of its start
and seed."""

import numpy as np

from lonlib.config import DDPGConfig, GymnasiumTaskConfig
from lonlib.ddpg.gymnasium_search import gymnasium_local_search
from lonlib.task import GymnasiumTask

PENDULUM = GymnasiumTask(GymnasiumTaskConfig("Pendulum-v1", (-3254.72, 0.0)))


def start(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return PENDULUM.actor_spec.initial(rng), PENDULUM.critic_spec.initial(rng)


def test_it_learns_to_swing_up_and_hold_pendulum_v1():
    """From a random start (fitness ~0.68, the pendulum never up) DDPG balances within 12k
    env steps (measured: first >= 0.95 after ~9k)."""
    theta, omega = start()
    hp = DDPGConfig(
        batch_size=256,
        buffer_size=50_000,
        warmup_steps=1000,
        max_steps=12_000,
        min_steps=12_000,
        patience_steps=12_000,
    )
    result = gymnasium_local_search(PENDULUM, theta, omega, hp, seed=5)
    assert result.start_fitness < 0.75 and result.fitness > 0.95
    # what it returns is what its Actor scores, by the one fitness function
    assert PENDULUM.fitness(result.theta[None])[0] == result.fitness


def test_the_start_is_no_candidate_and_the_search_is_deterministic():
    theta, omega = start(1)
    hp = DDPGConfig(
        batch_size=16,
        buffer_size=500,
        warmup_steps=300,
        max_steps=800,
        min_steps=0,
        patience_steps=10_000,
    )
    one = gymnasium_local_search(PENDULUM, theta, omega, hp, seed=3)
    two = gymnasium_local_search(PENDULUM, theta, omega, hp, seed=3)
    assert np.array_equal(one.theta, two.theta) and one.fitness == two.fitness
    judged = [r.greedy_fitness for r in one.history if not np.isnan(r.greedy_fitness)]
    assert one.fitness == max(judged)  # the best judged trained policy, not the start
    # the first episode (200 steps) ends in the warm-up: its policy is the start, not judged
    assert one.history[0].env_steps == 200 and np.isnan(one.history[0].greedy_fitness)
    counted = gymnasium_local_search(
        PENDULUM, theta, omega, DDPGConfig(**{**hp.__dict__, "count_start": True}), seed=3
    )
    assert counted.fitness >= counted.start_fitness
