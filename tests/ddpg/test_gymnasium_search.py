"""lonlib's DDPG on a Gymnasium task (``lonlib.ddpg.gymnasium_search``): it learns, it keeps
the slot trainer's rules of what it returns, and it is a deterministic function of its start
and seed."""

import dataclasses

import gymnasium
import numpy as np
import pytest

from lonlib.config import DDPGConfig, GymnasiumTaskConfig
from lonlib.ddpg.gymnasium_search import (
    GymnasiumSlotTrainer,
    SlotEnvironmentError,
    gymnasium_local_search,
)
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


SHORT = GymnasiumTask(GymnasiumTaskConfig("Pendulum-v1", (-3254.72, 0.0), episode_steps=40))
BATCHED = DDPGConfig(
    batch_size=16, buffer_size=400, warmup_steps=80, max_steps=480, min_steps=0, patience_steps=120
)


def short_start(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return SHORT.actor_spec.initial(rng), SHORT.critic_spec.initial(rng)


def assert_same_search(one, two):
    assert np.array_equal(one.theta, two.theta) and np.array_equal(one.omega, two.omega)
    assert (one.fitness, one.start_fitness, one.env_steps, one.updates, one.stop_reason) == (
        two.fitness,
        two.start_fitness,
        two.env_steps,
        two.updates,
        two.stop_reason,
    )
    strip = [{**vars(r), "seconds": 0} for r in one.history]
    assert str(strip) == str([{**vars(r), "seconds": 0} for r in two.history])


def test_a_batch_of_searches_is_bit_for_bit_each_search_alone():
    """Three searches through one batch of two slots: the third refills the slot the first
    frees while the second is mid-training, and the batch sheds the free slot when the
    second ends. Each returns exactly what it returns alone (own generator, own fresh
    environment, no reduction mixing agents)."""
    from tests.task.test_gymnasium_task import Line  # noqa: F401 (registers Line-v0)

    task = GymnasiumTask(GymnasiumTaskConfig("lonlib-test/Line-v0", (-200.0, 0.0)))
    hp = dataclasses.replace(BATCHED, warmup_steps=40, max_steps=600, patience_steps=100)
    seeds = [0, 3, 2]  # alone they stop after 140, 260 and 220 env steps

    def begin(seed):
        rng = np.random.default_rng(seed)
        return task.actor_spec.initial(rng)[None], task.critic_spec.initial(rng)[None]

    alone = [gymnasium_local_search(task, begin(s)[0][0], begin(s)[1][0], hp, s) for s in seeds]
    assert [r.env_steps for r in alone] == [140, 260, 220]
    first, second = begin(seeds[0]), begin(seeds[1])
    trainer = GymnasiumSlotTrainer(
        task,
        np.concatenate([first[0], second[0]]),
        np.concatenate([first[1], second[1]]),
        seeds[:2],
        hp,
        tags=["a", "b"],
    )
    assert trainer.vector.num_envs == 2  # the training environments: one vector env
    got = {}
    while trainer.busy.any():
        for tag, result in trainer.step():
            got[tag] = result
            if tag == "a":
                trainer.start(trainer.free_slots(), *begin(seeds[2]), [seeds[2]], ["c"])
            else:
                trainer.shrink()
    assert trainer.slots == 1 and trainer.vector.num_envs == 1
    for tag, result in zip("abc", alone, strict=True):
        assert_same_search(got[tag], result)


def test_a_search_comes_out_as_it_did_when_the_worked_examples_were_sampled():
    """A golden digest of one small search (its returned Actor, fitness and steps): lonlib's
    Gymnasium DDPG gives the bits it gave before the batched trainer replaced the one-agent
    loop (the committed worked examples resume on it)."""
    import hashlib

    theta, omega = short_start(7)
    result = gymnasium_local_search(SHORT, theta, omega, BATCHED, seed=11)
    digest = hashlib.sha256(result.theta.tobytes() + result.omega.tobytes()).hexdigest()
    assert (result.env_steps, result.stop_reason) == GOLDEN[:2]
    assert result.fitness == GOLDEN[2] and digest == GOLDEN[3]


def test_a_failing_environment_in_a_batch_names_its_search():
    from tests.task.test_gymnasium_task import Line  # noqa: F401 (registers Line-v0)

    task = GymnasiumTask(GymnasiumTaskConfig("lonlib-test/Line-v0", (-200.0, 0.0)))
    rng = np.random.default_rng(0)
    thetas = np.stack([task.actor_spec.initial(rng) for _ in range(2)])
    omegas = np.stack([task.critic_spec.initial(rng) for _ in range(2)])
    trainer = GymnasiumSlotTrainer(task, thetas, omegas, [0, 1], BATCHED, tags=["a", "b"])
    trainer.envs[1].env.unwrapped.fault = "nan-reward"  # the second slot's env, at step 3
    trainer.step(), trainer.step()
    with pytest.raises(SlotEnvironmentError) as error:
        trainer.step()
    assert error.value.tag == "b" and "reward nan at step 3" in str(error.value)


GOLDEN = (
    200,
    "patience",
    0.9302316212837491,
    "e31576f104570f84a6d0fd83eac69d9b82b50ee501dc60b0a4eee80c5132ebcb",
)


class IntegerObservations(gymnasium.Env):
    """A counter observed as uint8: the scaled float observations must not be cast back."""

    observation_space = gymnasium.spaces.Box(0, 255, (1,), np.uint8)
    action_space = gymnasium.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.array([0], dtype=np.uint8), {}

    def step(self, action):
        self.t += 1
        return np.array([self.t], dtype=np.uint8), -abs(float(action[0])), False, False, {}


gymnasium.register("lonlib-test/IntegerObservations-v0", IntegerObservations, max_episode_steps=20)


def test_an_integer_observation_space_trains():
    task = GymnasiumTask(GymnasiumTaskConfig("lonlib-test/IntegerObservations-v0", (-20.0, 0.0)))
    rng = np.random.default_rng(0)
    hp = dataclasses.replace(BATCHED, warmup_steps=20, max_steps=60)
    result = gymnasium_local_search(
        task, task.actor_spec.initial(rng), task.critic_spec.initial(rng), hp, 0
    )
    assert result.env_steps == 60 and 0 <= result.fitness <= 1
