"""DDPG local search: validation, k agents = k single agents, stopping, learning."""

import numpy as np
import pytest

from lonlib.ddpg import DDPGConfig, is_improvement, local_search, local_search_batch
from lonlib.nets import actor_spec, critic_spec
from lonlib.pendulum import PendulumConfig

SMALL = {"batch_size": 64, "buffer_size": 2000, "warmup_steps": 100, "min_steps": 0}


def initial(n_carts, k, seed=0):
    rng = np.random.default_rng(seed)
    thetas = np.stack([actor_spec(n_carts).initial(rng) for _ in range(k)])
    omegas = np.stack([critic_spec(n_carts).initial(rng) for _ in range(k)])
    return thetas, omegas


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("buffer_size", 0),
        ("batch_size", -1),
        ("noise_std", -0.1),
        ("learning_rate", 0.0),
        ("gamma", 1.5),
        ("tau", 0.0),
        ("warmup_steps", 0),
        ("max_steps", 0),
        ("patience_steps", 0),
        ("threads", 0),
        ("min_steps", 10**9),
        ("device", "nonsense"),
        ("batch_size", 2.5),
        ("update", "fast"),
    ],
)
def test_invalid_hyperparameters_are_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field if field != "device" else "device"):
        DDPGConfig(**{field: value})


def test_nan_parameters_are_refused_before_training():
    theta, omega = initial(2, 1)
    theta[0, 5] = np.nan
    with pytest.raises(ValueError, match="theta"):
        local_search(theta[0], omega[0], PendulumConfig(), DDPGConfig(**SMALL), seed=0)


def test_three_agents_together_equal_each_alone():
    env = PendulumConfig(n_carts=2, steps=100, initial_noise=0.02)
    hp = DDPGConfig(max_steps=400, patience_steps=10**6, **SMALL)  # 300 updates each
    thetas, omegas = initial(2, 3)
    together = local_search_batch(thetas, omegas, env, hp, seeds=[5, 6, 7])
    for i, seed in enumerate([5, 6, 7]):
        alone = local_search(thetas[i], omegas[i], env, hp, seed=seed)
        assert len(alone.history) == len(together[i].history)
        got = [h.episode_return for h in together[i].history]
        want = [h.episode_return for h in alone.history]
        np.testing.assert_allclose(got, want, atol=1e-3)
        np.testing.assert_allclose(together[i].theta, alone.theta, atol=1e-4)
        np.testing.assert_allclose(together[i].omega, alone.omega, atol=1e-4)
        assert together[i].fitness == pytest.approx(alone.fitness, abs=1e-9)


def test_same_seed_same_result_and_history_is_complete():
    env = PendulumConfig(n_carts=1, steps=60)
    hp = DDPGConfig(max_steps=300, patience_steps=10**6, **SMALL)
    theta, omega = initial(1, 1)
    a = local_search(theta[0], omega[0], env, hp, seed=3)
    b = local_search(theta[0], omega[0], env, hp, seed=3)
    np.testing.assert_array_equal(a.theta, b.theta)
    assert [h.episode_return for h in a.history] == [h.episode_return for h in b.history]
    assert a.env_steps == 300 and a.stop_reason == "budget"
    assert a.history[-1].env_steps <= 300
    assert all(np.isnan(h.critic_loss) for h in a.history if h.env_steps < 100)
    assert all(np.isfinite(h.critic_loss) for h in a.history if h.env_steps > 160)
    assert a.fitness >= a.initial_fitness  # the start point counts as seen


def test_patience_stops_a_search_that_does_not_improve():
    env = PendulumConfig(n_carts=1, steps=50)
    hp = DDPGConfig(max_steps=5000, patience_steps=200, plateau_tiebreak=False, **SMALL)
    theta, omega = initial(1, 1)
    result = local_search(theta[0], omega[0], env, hp, seed=0)
    assert result.stop_reason == "patience"
    assert result.env_steps < 5000


def test_plateau_tiebreak_counts_return_progress_only_on_equal_fitness():
    assert is_improvement((0.2, -9.0), (0.1, 50.0), plateau_tiebreak=True)
    assert not is_improvement((0.1, 60.0), (0.2, 0.0), plateau_tiebreak=True)
    assert is_improvement((0.0, 3.0), (0.0, 2.0), plateau_tiebreak=True)
    assert not is_improvement((0.0, 3.0), (0.0, 2.0), plateau_tiebreak=False)
    assert not is_improvement((0.0, 2.0), (0.0, 2.0), plateau_tiebreak=True)


def test_ddpg_learns_a_task_with_known_good_behaviour():
    """Swing the hanging rod high: reward is height, "upright" means within ~37 degrees of
    horizontal or above. An untrained Actor barely moves the rod (fitness 0); a policy that
    pumps energy scores well. DDPG must beat the untrained policy by a clear margin."""
    env = PendulumConfig(
        n_carts=1, steps=150, upright_angle=2.5, motor="acceleration", motor_gain=2.0
    )
    hp = DDPGConfig(
        batch_size=128,
        buffer_size=10_000,
        warmup_steps=1000,
        max_steps=5000,
        min_steps=0,
        patience_steps=10**6,
    )
    thetas, omegas = initial(1, 3)
    results = local_search_batch(thetas, omegas, env, hp, seeds=[0, 1, 2])
    for result in results:
        assert result.initial_fitness == 0.0
        assert result.fitness >= result.initial_fitness + 0.1
