"""SB3 local searches: deterministic (the same search twice gives the same parameters), the
process's global random state left as found, and lonlib's judging rules (patience, judging
interval, the Actor at the stop, a search that never trains)."""

import random

import numpy as np
import pytest
import torch

from lonlib.sb3.search import sb3_local_search
from lonlib.search.algorithm import random_networks
from tests.sb3.toy import pendulum_task, tiny_hp


def start(task, seed=3):
    return random_networks(seed, task.actor_spec, task.critic_spec, task.critic_count)


@pytest.mark.parametrize("search", ["sb3-td3", "sb3-sac"])
def test_the_same_search_twice_gives_identical_parameters(search):
    task = pendulum_task(search)
    theta, omega = start(task)
    hp = tiny_hp(max_steps=150)
    legacy = np.random.get_state()[1]  # noqa: NPY002 (the legacy generator SB3 seeds)
    python, generator = random.getstate(), torch.get_rng_state()
    first = sb3_local_search(task, theta, omega, hp, seed=2**63 + 5, search=search)
    assert np.array_equal(np.random.get_state()[1], legacy)  # noqa: NPY002 (undone)
    assert random.getstate() == python and torch.equal(torch.get_rng_state(), generator)
    second = sb3_local_search(task, theta, omega, hp, seed=2**63 + 5, search=search)
    np.testing.assert_array_equal(first.theta, second.theta)
    np.testing.assert_array_equal(first.omega, second.omega)
    assert first.fitness == second.fitness and first.updates == second.updates == 100
    assert [r.greedy_fitness for r in first.history] == pytest.approx(
        [r.greedy_fitness for r in second.history], nan_ok=True, rel=0, abs=0
    )
    assert not np.array_equal(first.theta, theta)  # it trained
    other = sb3_local_search(task, theta, omega, hp, seed=6, search=search)
    assert not np.array_equal(other.theta, first.theta)  # the seed matters
    assert first.omega.shape == (2 * task.critic_spec.n_params,)


def test_patience_stops_the_search_after_its_last_improvement():
    task = pendulum_task("sb3-td3", episode_steps=25)
    theta, omega = start(task)
    result = sb3_local_search(
        task, theta, omega, tiny_hp(max_steps=400, patience_steps=60), seed=1, search="sb3-td3"
    )
    best, last = -np.inf, 50  # the patience window opens at the end of the warm-up
    for record in result.history:
        if record.greedy_fitness > best:
            best, last = record.greedy_fitness, max(record.env_steps, 50)
    assert result.stop_reason == "patience" and result.env_steps == last + 60
    assert result.fitness == best and result.history[-1].env_steps <= result.env_steps
    assert [r.env_steps for r in result.history] == list(range(25, result.env_steps + 1, 25))
    judged = [r.env_steps for r in result.history if not np.isnan(r.greedy_fitness)]
    assert judged == [s for s in range(75, result.env_steps + 1, 25)]  # once it trains


def test_judge_every_and_the_actor_at_the_stop():
    task = pendulum_task("sb3-ddpg", episode_steps=25)
    theta, omega = start(task)
    hp = tiny_hp(max_steps=150, judge_every=60)
    result = sb3_local_search(task, theta, omega, hp, seed=1, search="sb3-ddpg")
    judged = [r.env_steps for r in result.history if not np.isnan(r.greedy_fitness)]
    assert judged == [75, 125]  # the episode ends crossing 60 and 120 (after the warm-up)
    assert result.env_steps == 150 and result.stop_reason == "budget"
    never = sb3_local_search(
        task, theta, omega, tiny_hp(max_steps=150, judge_every=1000), 1, "sb3-ddpg"
    )
    assert never.final_evaluation and never.fitness == task.fitness(never.theta[None])[0]
    assert never.updates == 100 and not np.array_equal(never.theta, theta)


def test_a_search_that_never_trains_returns_its_start_exactly():
    task = pendulum_task("sb3-sac", episode_steps=25)
    theta, omega = start(task)
    hp = tiny_hp(warmup_steps=50, max_steps=50)  # SB3 trains after the step past the warm-up
    result = sb3_local_search(task, theta, omega, hp, seed=1, search="sb3-sac")
    assert result.updates == 0 and result.final_evaluation
    np.testing.assert_array_equal(result.theta, theta)
    np.testing.assert_array_equal(result.omega, omega)
    assert result.fitness == result.start_fitness == task.fitness(theta[None])[0]
