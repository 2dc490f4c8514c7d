"""The Gymnasium facade: registration, spaces, semantics, rendering."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import lonlib  # noqa: F401  (registers the environment)
from lonlib.task.env import ENV_ID


@pytest.mark.parametrize("n_carts", [1, 2, 5])
def test_check_env_passes_and_spaces_follow_the_cart_count(n_carts):
    env = gym.make(ENV_ID, n_carts=n_carts)
    check_env(env.unwrapped)
    assert env.observation_space.shape == (10 * n_carts,)
    assert env.action_space.shape == (n_carts,)
    assert env.unwrapped.config.n_carts == n_carts


def test_keyword_arguments_reach_the_config_and_bad_ones_are_refused():
    env = gym.make(ENV_ID, n_carts=1, reward="upright", steps=123)
    assert env.unwrapped.config.reward == "upright" and env.unwrapped.config.steps == 123
    with pytest.raises(ValueError, match="n_carts"):
        gym.make(ENV_ID, n_carts=9)


def test_truncated_at_step_limit_not_terminated():
    env = gym.make(ENV_ID, n_carts=2, steps=30)
    env.reset(seed=0)
    for k in range(1, 31):
        _, _, terminated, truncated, info = env.step(np.full(2, 0.5, dtype=np.float32))
        assert not terminated and truncated == (k == 30)
    assert info["end_reason"] == "STEP_LIMIT" and info["fitness"] == 0.0


def test_terminated_on_boundary_with_penalty_and_reason():
    env = gym.make(ENV_ID, n_carts=1)
    env.reset(seed=0)
    terminated = truncated = False
    while not (terminated or truncated):
        _, reward, terminated, truncated, info = env.step(np.ones(1, dtype=np.float32))
    assert terminated and not truncated and info["end_reason"] == "BOUNDARY"
    assert reward < -4.0  # height reward in [0, 1] plus the -5 termination penalty
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.ones(1, dtype=np.float32))


def test_random_policy_earns_a_height_signal_in_its_first_episode():
    env = gym.make(ENV_ID, n_carts=2)
    env.action_space.seed(0)
    env.reset(seed=0)
    height = 0.0
    terminated = truncated = False
    while not (terminated or truncated):
        _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        if not terminated:
            height += reward
    assert height > 0.05


def test_same_seed_same_episode_with_initial_noise():
    def run(seed):
        env = gym.make(ENV_ID, n_carts=2, initial_noise=0.05)
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for _ in range(20):
            out.append(env.step(np.array([0.7, 0.2], dtype=np.float32))[0])
        return np.stack(out)

    np.testing.assert_array_equal(run(4), run(4))
    assert not np.array_equal(run(4), run(5))


def test_render_rgb_array_draws_carts_and_rods():
    env = gym.make(ENV_ID, n_carts=2, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    blue = (frame == np.array([40, 90, 170], dtype=np.uint8)).all(axis=2).sum()
    red = (frame == np.array([200, 60, 40], dtype=np.uint8)).all(axis=2).sum()
    assert blue > 100 and red > 50  # two carts and two rods are on the picture
    no_render = gym.make(ENV_ID)
    no_render.reset(seed=0)
    assert no_render.render() is None


def test_v0_is_deprecated_and_makes_the_v1_environment():
    with pytest.warns(DeprecationWarning) as caught:  # ours, and Gymnasium's "out of date"
        old = gym.make("lonlib/CoupledPendulum-v0", n_carts=1)
    assert any("use lonlib/CoupledPendulum-v1" in str(w.message) for w in caught)
    assert ENV_ID == "lonlib/CoupledPendulum-v1"
    assert old.unwrapped.config == gym.make(ENV_ID, n_carts=1).unwrapped.config
