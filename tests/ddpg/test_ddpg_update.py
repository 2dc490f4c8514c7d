"""The lean DDPG learner is the autograd update, step for step, with its own slot resets."""

import numpy as np
import pytest
import torch

from lonlib.config import PendulumConfig
from lonlib.ddpg.lean import LeanDDPG
from lonlib.ddpg.learner import learner_class
from lonlib.ddpg.reference import AutogradDDPG
from lonlib.ddpg.search import local_search_batch
from lonlib.task.policy import actor_spec, critic_spec, forward_numpy
from tests.conftest import tiny_ddpg

HP = {"learning_rate": 1e-3, "gamma": 0.99, "tau": 0.005}
DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def initial(n_carts, k, seed=0):
    rng = np.random.default_rng(seed)
    thetas = np.stack([actor_spec(n_carts).initial(rng) for _ in range(k)])
    omegas = np.stack([critic_spec(n_carts).initial(rng) for _ in range(k)])
    return thetas, omegas


def random_batch(generator, k, size, n_carts, device):
    """``(s, a, r, s', not_done)`` with about a third of the rows terminal (not_done = 0)."""

    def uniform(*shape):
        return torch.rand(*shape, generator=generator).to(device)

    obs, next_obs = uniform(k, size, 10 * n_carts), uniform(k, size, 10 * n_carts)
    rewards = 4 * uniform(k, size, 1) - 2
    not_done = (uniform(k, size, 1) > 0.35).float()
    return obs, uniform(k, size, n_carts), rewards, next_obs, not_done


def assert_same_state(got, want):
    """Every array agrees to float tolerance relative to its own scale."""
    assert got.keys() == want.keys()
    for name in want:
        scale = np.abs(want[name]).max()
        np.testing.assert_allclose(got[name], want[name], rtol=0, atol=2e-5 * scale, err_msg=name)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize(("k", "n_carts"), [(1, 2), (3, 1)])
def test_lean_update_equals_autograd_update(k, n_carts, device):
    thetas, omegas = initial(n_carts, k)
    lean = LeanDDPG(actor_spec(n_carts), critic_spec(n_carts), thetas, omegas, **HP, device=device)
    reference = AutogradDDPG(
        actor_spec(n_carts), critic_spec(n_carts), thetas, omegas, **HP, device=device
    )
    generator = torch.Generator().manual_seed(k)
    for _ in range(4):
        batch = random_batch(generator, k, 48, n_carts, device)
        got, want = lean.update(batch), reference.update(batch)
        np.testing.assert_allclose(got[0], want[0], rtol=1e-5)  # critic losses
        np.testing.assert_allclose(got[1], want[1], rtol=1e-5, atol=1e-7)  # actor losses
        assert_same_state(lean.state(), reference.state())
    obs = torch.rand(k, 10 * n_carts, generator=generator).to(device)
    torch.testing.assert_close(lean.act(obs), reference.act(obs))


def test_not_done_masks_the_bootstrap():
    """Only the terminal rows' targets change with the next state's value: with every row
    terminal the critic's first step does not depend on s'."""
    thetas, omegas = initial(1, 2)
    generator = torch.Generator().manual_seed(0)
    batch = list(random_batch(generator, 2, 32, 1, "cpu"))
    batch[4] = torch.zeros_like(batch[4])
    results = []
    for next_obs in (batch[3], 1 - batch[3]):
        lean = LeanDDPG(actor_spec(1), critic_spec(1), thetas, omegas, **HP)
        results.append(lean.update((*batch[:3], next_obs, batch[4])))
    np.testing.assert_array_equal(results[0][0], results[1][0])


def test_parameters_round_trip_and_greedy_actions_match_numpy():
    thetas, omegas = initial(3, 2)
    lean = LeanDDPG(actor_spec(3), critic_spec(3), thetas, omegas, **HP)
    np.testing.assert_array_equal(lean.actor_flat(), thetas)
    np.testing.assert_array_equal(lean.critic_flat(), omegas)
    obs = np.random.default_rng(1).uniform(size=(2, 30)).astype(np.float32)
    want = np.stack([forward_numpy(actor_spec(3), thetas[i], obs[i : i + 1])[0] for i in range(2)])
    np.testing.assert_allclose(lean.act(torch.from_numpy(obs)).numpy(), want, atol=1e-6)


def test_reset_agent_restarts_one_slot_and_leaves_the_others():
    thetas, omegas = initial(2, 3)
    fresh_theta, fresh_omega = initial(2, 1, seed=9)
    lean = LeanDDPG(actor_spec(2), critic_spec(2), thetas, omegas, **HP)
    untouched = LeanDDPG(actor_spec(2), critic_spec(2), thetas, omegas, **HP)
    alone = AutogradDDPG(actor_spec(2), critic_spec(2), fresh_theta, fresh_omega, **HP)
    generator = torch.Generator().manual_seed(3)
    batches = [random_batch(generator, 3, 40, 2, "cpu") for _ in range(5)]
    for batch in batches[:2]:
        lean.update(batch)
        untouched.update(batch)
    lean.reset_agent(1, fresh_theta[0], fresh_omega[0])
    for batch in batches[2:]:
        lean.update(batch)
        untouched.update(batch)
        alone.update(tuple(part[1:2] for part in batch))
    got, others = lean.state(), untouched.state()
    for name, values in got.items():
        np.testing.assert_array_equal(values[[0, 2]], others[name][[0, 2]], err_msg=name)
    assert_same_state({key: value[1:2] for key, value in got.items()}, alone.state())


def test_bad_shapes_and_kinds_are_refused():
    thetas, omegas = initial(2, 2)
    with pytest.raises(ValueError, match="parameters"):
        LeanDDPG(actor_spec(2), critic_spec(2), thetas[:, :-1], omegas, **HP)
    with pytest.raises(ValueError, match="critic sizes"):
        LeanDDPG(actor_spec(2), critic_spec(1), thetas, omegas, **HP)
    with pytest.raises(ValueError, match="update"):
        learner_class("fast")
    with pytest.raises(ValueError, match="agent"):
        LeanDDPG(actor_spec(2), critic_spec(2), thetas, omegas, **HP).reset_agent(2, *initial(2, 1))


@pytest.mark.parametrize("device", DEVICES)
def test_local_search_is_the_same_with_either_learner(device):
    env = PendulumConfig(n_carts=1, steps=40, initial_noise=0.02)
    thetas, omegas = initial(1, 2)
    runs = {
        kind: local_search_batch(
            thetas,
            omegas,
            env,
            tiny_ddpg(max_steps=160, update=kind, device=device),
            seeds=[1, 2],
        )
        for kind in ("lean", "autograd")
    }
    for lean, reference in zip(runs["lean"], runs["autograd"], strict=True):
        assert len(lean.history) == len(reference.history) >= 3
        np.testing.assert_allclose(
            [h.critic_loss for h in lean.history],
            [h.critic_loss for h in reference.history],
            rtol=1e-4,
        )
        np.testing.assert_allclose(lean.theta, reference.theta, atol=1e-5)
        np.testing.assert_allclose(lean.omega, reference.omega, atol=1e-5)
