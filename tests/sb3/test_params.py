"""lonlib's flat Actor and Critic in an SB3 policy: the same functions on both sides (the
Actor's sigmoid output onto the bounds is SB3's tanh output onto them; each critic's Q of an
action in [0, 1] is SB3's of the same action in [-1, 1]), the targets copied."""

import numpy as np
import pytest
import torch

from lonlib.sb3 import SB3_SEARCHES
from lonlib.sb3.env import TrainingEnv
from lonlib.sb3.model import make_model
from lonlib.sb3.params import actor_theta, critic_omega, load_parameters
from lonlib.search.algorithm import random_networks
from lonlib.task.policy import forward_numpy
from tests.sb3.toy import tiny_hp, toy_task


def loaded(search: str):
    """(task, model, theta, omega): random parameters, the Actor's spread so that its
    outputs cover (0, 1), loaded into a fresh SB3 model of ``search`` on the toy task."""
    task = toy_task(search)
    theta, omega = random_networks(5, task.actor_spec, task.critic_spec, task.critic_count)
    theta = theta * np.float32(3.0)
    model = make_model(search, TrainingEnv(task, "test"), tiny_hp(), seed=1)
    load_parameters(model.policy, theta, omega, task.actor_spec, task.critic_spec)
    return task, model, theta, omega


@pytest.mark.parametrize("search", SB3_SEARCHES)
def test_lonlibs_forward_of_theta_is_sb3s_deterministic_action(search):
    task, model, theta, _ = loaded(search)
    obs = np.random.default_rng(0).uniform(-1.5, 1.5, (16, task.obs_size))
    ours = task.env_action(forward_numpy(task.actor_spec, theta, obs))
    unit, _ = model.predict(obs.astype(np.float32), deterministic=True)
    theirs = task.env_action(unit)
    span = task.action_span.astype(np.float32)
    assert (np.ptp(ours, axis=0) > 0.02 * span).all()  # the actions vary with the observation
    np.testing.assert_allclose(theirs, ours, rtol=0, atol=2e-6 * span.max())
    np.testing.assert_array_equal(actor_theta(model.policy), theta)  # the round trip is exact


@pytest.mark.parametrize("search", SB3_SEARCHES)
def test_every_critic_of_omega_is_sb3s_q_of_the_same_action(search):
    task, model, _, omega = loaded(search)
    rng = np.random.default_rng(1)
    obs = rng.uniform(-1.5, 1.5, (16, task.obs_size))
    action = rng.uniform(0.0, 1.0, (16, task.action_size))
    with torch.no_grad():
        theirs = model.policy.critic(
            torch.as_tensor(obs, dtype=torch.float32),
            torch.as_tensor(2.0 * action - 1.0, dtype=torch.float32),  # SB3's units
        )
    size = task.critic_spec.n_params
    assert len(theirs) == task.critic_count == (1 if search == "sb3-ddpg" else 2)
    assert omega.shape == (task.critic_count * size,)
    for i, q in enumerate(theirs):
        critic = omega[i * size : (i + 1) * size]
        ours = forward_numpy(task.critic_spec, critic, np.hstack([obs, action]))
        np.testing.assert_allclose(q.numpy(), ours, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(critic_omega(model.policy, task.action_size), omega, atol=1e-6)


@pytest.mark.parametrize("search", SB3_SEARCHES)
def test_the_target_networks_start_as_the_loaded_ones(search):
    _, model, _, _ = loaded(search)
    policy = model.policy
    pairs = [(policy.critic, policy.critic_target)]
    if search != "sb3-sac":  # SAC has no actor target
        pairs.append((policy.actor, policy.actor_target))
    for online, target in pairs:
        for name, value in online.state_dict().items():
            assert torch.equal(value, target.state_dict()[name]), name


def test_omega_of_the_wrong_length_is_refused():
    task, model, theta, omega = loaded("sb3-td3")
    with pytest.raises(ValueError, match="2 critic"):
        load_parameters(model.policy, theta, omega[:-1], task.actor_spec, task.critic_spec)
