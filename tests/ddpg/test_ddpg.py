"""DDPG local search: validation, one update against a textbook DDPG, the replay's terminal
flags, what F returns, k agents = k single agents, stopping, and learning."""

import dataclasses

import numpy as np
import pytest
import torch

from lonlib.config import DDPGConfig, PendulumConfig
from lonlib.ddpg.replay import ReplayBuffer
from lonlib.ddpg.search import local_search, local_search_batch
from lonlib.ddpg.slots import is_improvement
from lonlib.ddpg.streams import EXPLORATION_NOISE, CounterStreams
from lonlib.ddpg.trainer import SlotTrainer, exploration_actions
from lonlib.task.pendulum import StepResult
from lonlib.task.policy import actor_spec, critic_spec, forward_numpy
from lonlib.task.rollout import evaluate, score_actors
from tests.ddpg.ddpg_reference import lonlib_updates, reference_updates

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
        ("warmup_steps", 10**6),
        ("device", "nonsense"),
        ("batch_size", 2.5),
        ("update", "fast"),
    ],
)
def test_invalid_hyperparameters_are_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field if field != "device" else "device"):
        DDPGConfig(**{field: value})


# ------------------------------------------------------------------ one update
def random_batches(n_carts, k, size, updates, done_share, seed=0):
    """``updates`` batches of ``[k, size, ...]`` transitions; ``done_share`` of them terminal."""
    rng = np.random.default_rng(seed)
    obs_size = 10 * n_carts
    return [
        (
            rng.uniform(0, 1, (k, size, obs_size)),
            rng.uniform(0, 1, (k, size, n_carts)),
            rng.uniform(-1, 1, (k, size, 1)),
            rng.uniform(0, 1, (k, size, obs_size)),
            (rng.uniform(0, 1, (k, size, 1)) >= done_share).astype(np.float64),
        )
        for _ in range(updates)
    ]


@pytest.mark.parametrize("kind", ["lean", "autograd"])
@pytest.mark.parametrize("done_share", [0.0, 0.5, 1.0])
def test_batched_update_equals_a_textbook_ddpg_update_per_agent(done_share, kind):
    """Critic target, terminal mask, actor ascent, critic frozen in the actor step, Adam and
    the soft target update, for each of k = 3 agents over 4 consecutive updates."""
    n, k = 1, 3
    a_spec, c_spec = actor_spec(n), critic_spec(n)
    hp = DDPGConfig(tau=0.05, gamma=0.9, learning_rate=3e-3, update=kind)
    thetas, omegas = initial(n, k, seed=4)
    batches = random_batches(n, k, 64, 4, done_share)
    got = lonlib_updates(a_spec, c_spec, thetas, omegas, batches, hp)
    for i in range(k):
        mine = [tuple(x[i] for x in batch) for batch in batches]
        want = reference_updates(a_spec, c_spec, thetas[i], omegas[i], mine, hp)
        np.testing.assert_allclose(got["losses"][i], want["losses"], rtol=1e-4, atol=1e-6)
        for key in ("theta", "omega", "theta_target", "omega_target"):
            np.testing.assert_allclose(got[key][i], want[key], atol=2e-5, err_msg=key)


def critic_input_loss(c_spec, omega, obs, actions, target):
    q = forward_numpy(c_spec, omega.astype(np.float64), np.concatenate([obs, actions], axis=1))
    return float(np.mean((q - target) ** 2))


@pytest.mark.parametrize("terminal", [True, False])
def test_critic_target_bootstraps_only_past_a_non_terminal_step(terminal):
    n = 1
    a_spec, c_spec = actor_spec(n), critic_spec(n)
    hp = DDPGConfig(gamma=0.95)
    thetas, omegas = initial(n, 1, seed=2)
    obs, act, rew, next_obs, not_done = random_batches(n, 1, 32, 1, float(terminal))[0]
    got = lonlib_updates(a_spec, c_spec, thetas, omegas, [(obs, act, rew, next_obs, not_done)], hp)
    next_a = forward_numpy(a_spec, thetas[0].astype(np.float64), next_obs[0])
    next_q = forward_numpy(
        c_spec, omegas[0].astype(np.float64), np.concatenate([next_obs[0], next_a], axis=1)
    )
    target = rew[0] + (0.0 if terminal else hp.gamma) * next_q
    want = critic_input_loss(c_spec, omegas[0], obs[0], act[0], target)
    assert got["losses"][0, 0, 0] == pytest.approx(want, rel=1e-4)


def test_soft_target_update_is_exact():
    n, k = 2, 2
    a_spec, c_spec = actor_spec(n), critic_spec(n)
    hp = DDPGConfig(tau=0.2)
    thetas, omegas = initial(n, k, seed=3)
    got = lonlib_updates(a_spec, c_spec, thetas, omegas, random_batches(n, k, 16, 1, 0.3), hp)
    np.testing.assert_allclose(got["theta_target"], 0.8 * thetas + 0.2 * got["theta"], atol=1e-6)
    np.testing.assert_allclose(got["omega_target"], 0.8 * omegas + 0.2 * got["omega"], atol=1e-6)
    assert not np.allclose(got["theta"], thetas)  # the nets moved, so the test can see tau


@pytest.mark.parametrize("kind", ["lean", "autograd"])
def test_actor_step_raises_the_critics_value_of_its_actions(kind):
    n, k = 1, 3
    a_spec, c_spec = actor_spec(n), critic_spec(n)
    hp = DDPGConfig(learning_rate=1e-3, update=kind)
    thetas, omegas = initial(n, k, seed=5)
    batch = random_batches(n, k, 128, 1, 0.2)[0]
    got = lonlib_updates(a_spec, c_spec, thetas, omegas, [batch], hp)
    for i in range(k):
        obs, critic = batch[0][i], got["omega"][i].astype(np.float64)

        def q(theta, obs=obs, critic=critic):
            actions = forward_numpy(a_spec, theta.astype(np.float64), obs)
            return forward_numpy(c_spec, critic, np.concatenate([obs, actions], axis=1)).mean()

        assert q(got["theta"][i]) > q(thetas[i])


# ------------------------------------------------------------------ replay
def test_only_a_true_end_is_stored_as_terminal_and_truncation_bootstraps():
    replay = ReplayBuffer(3, 8, obs_size=10, act_size=1, device=torch.device("cpu"))
    outcome = StepResult(
        reward=np.array([0.1, 0.2, 0.3]),
        upright=np.zeros(3),
        upright_each=np.zeros((3, 1), dtype=bool),
        terminated=np.array([True, False, False]),
        truncated=np.array([False, True, False]),
        end_reason=np.zeros(3, dtype=np.int8),
    )
    obs = np.random.default_rng(0).uniform(size=(3, 10)).astype(np.float32)
    actions = torch.full((3, 1), 0.7, dtype=torch.float64)  # s and a: on the device already
    stored_next = replay.add_step(torch.from_numpy(obs), actions, outcome, obs + 1)
    np.testing.assert_array_equal(stored_next.numpy(), obs + 1)
    s, a, r, s2, not_done = replay.sample(np.zeros((3, 1), dtype=np.int64))
    assert not_done[:, 0, 0].tolist() == [0.0, 1.0, 1.0]
    np.testing.assert_allclose(r[:, 0, 0], [0.1, 0.2, 0.3], rtol=1e-6)
    np.testing.assert_allclose(s2[:, 0].numpy(), obs + 1)
    np.testing.assert_allclose(s[:, 0].numpy(), obs)
    np.testing.assert_allclose(a[:, 0, 0], 0.7, rtol=1e-6)


def test_each_slot_is_a_ring_of_its_capacity_that_a_clear_empties():
    replay = ReplayBuffer(2, 4, obs_size=1, act_size=1, device=torch.device("cpu"))
    for step in range(6):
        obs, actions = torch.full((2, 1), float(step)), torch.zeros(2, 1, dtype=torch.float64)
        ends = np.zeros(2, dtype=bool)
        replay.add(obs, actions, np.zeros(2), np.full((2, 1), step + 1.0), ends)
    assert replay.size.tolist() == [4, 4] and replay.position.tolist() == [2, 2]
    s, *_, s2, _ = replay.sample(torch.arange(4).repeat(2, 1))
    assert s[0, :, 0].tolist() == [4.0, 5.0, 2.0, 3.0]  # steps 4 and 5 overwrote rows 0, 1
    assert s2[1, :, 0].tolist() == [5.0, 6.0, 3.0, 4.0]
    replay.clear(1)
    assert replay.size.tolist() == [4, 0] and replay.position.tolist() == [2, 0]


def test_exploration_noise_has_the_configured_standard_deviation_and_is_clipped():
    streams = CounterStreams(list(range(4000)))
    noise = streams.normal(EXPLORATION_NOISE, np.zeros(4000, dtype=np.int64), 2)
    actions = exploration_actions(torch.full((4000, 2), 0.5), noise, 0.1).numpy()
    assert np.std(actions - 0.5) == pytest.approx(0.1, rel=0.05)
    assert abs(np.mean(actions - 0.5)) < 0.01
    edge = exploration_actions(torch.full((4000, 2), 0.99), noise, 0.1).numpy()
    assert edge.max() == 1.0 and (edge <= 1.0).all() and (edge < 0.99).any()


# ------------------------------------------------------------------ what F returns
def upright_hold_start(n_carts=1, seed=0):
    """A start whose Actor outputs exactly 0.5 (no push): with the rod upright at rest it
    scores the maximum fitness 1, and any trained change of the Actor lets the rod fall."""
    thetas, omegas = initial(n_carts, 1, seed)
    spec = actor_spec(n_carts)
    weight_start, _, bias_end = spec.offsets[-1]
    thetas[0, weight_start:bias_end] = 0.0
    return thetas[0], omegas[0]


UPRIGHT_ENV = PendulumConfig(n_carts=1, steps=400, initial_angle=0.0)


@pytest.mark.parametrize("count_start", [False, True])
def test_returned_parameters_rescore_to_the_returned_fitness(count_start):
    theta, omega = upright_hold_start()
    hp = DDPGConfig(max_steps=450, patience_steps=10**6, count_start=count_start, **SMALL)
    result = local_search(theta, omega, UPRIGHT_ENV, hp, seed=1)
    assert result.start_fitness == 1.0
    rescored = score_actors(result.theta, UPRIGHT_ENV, hp.scoring).fitness[0]
    assert rescored == result.fitness
    if count_start:  # the start is seen and nothing trained beats a perfect score
        assert result.fitness == 1.0
        np.testing.assert_array_equal(result.theta, theta)
        np.testing.assert_array_equal(result.omega, omega)
    else:  # only trained policies are candidates: the perfect start is not returned
        assert result.fitness < 1.0 and not result.improved
        assert not np.array_equal(result.theta, theta)
        assert not np.array_equal(result.omega, omega)


def test_a_search_with_no_finished_training_episode_returns_the_trained_actor():
    env = PendulumConfig(n_carts=1, steps=1000, initial_angle=0.0)  # episodes outlast the budget
    theta, omega = upright_hold_start()
    hp = DDPGConfig(max_steps=180, patience_steps=10**6, **SMALL)
    result = local_search(theta, omega, env, hp, seed=0)
    assert result.final_evaluation and result.updates == 81
    assert result.history == [] or all(h.env_steps < 100 for h in result.history)
    assert not np.array_equal(result.theta, theta)
    assert not np.array_equal(result.omega, omega)
    assert score_actors(result.theta, env, hp.scoring).fitness[0] == result.fitness


def test_nan_parameters_are_refused_before_training():
    theta, omega = initial(2, 1)
    theta[0, 5] = np.nan
    with pytest.raises(ValueError, match="theta"):
        local_search(theta[0], omega[0], PendulumConfig(), DDPGConfig(**SMALL), seed=0)


def test_three_agents_together_equal_each_alone_bit_for_bit():
    # Patience stops the agents at different steps, so the batch sheds finished agents
    # (SlotTrainer.shrink) while the others train on: nothing may change for them.
    env = PendulumConfig(n_carts=2, steps=60, initial_noise=0.02, upright_angle=2.9)
    hp = DDPGConfig(max_steps=900, patience_steps=150, plateau_tiebreak=True, **SMALL)
    thetas, omegas = initial(2, 3)
    together = local_search_batch(thetas, omegas, env, hp, seeds=[5, 6, 7])
    assert len({r.env_steps for r in together}) > 1
    for i, seed in enumerate([5, 6, 7]):
        alone = local_search(thetas[i], omegas[i], env, hp, seed=seed)
        assert len(alone.history) == len(together[i].history)
        for a, b in zip(alone.history, together[i].history, strict=True):
            assert dataclasses.replace(a, seconds=0) == dataclasses.replace(b, seconds=0)
        np.testing.assert_array_equal(together[i].theta, alone.theta)
        np.testing.assert_array_equal(together[i].omega, alone.omega)
        assert (together[i].fitness, together[i].env_steps) == (alone.fitness, alone.env_steps)


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
    assert all(np.isnan(h.greedy_fitness) for h in a.history if h.env_steps < 100)


@pytest.mark.parametrize(
    ("patience", "min_steps", "tiebreak"),
    [(200, 0, False), (50, 0, False), (50, 1000, False), (300, 0, True)],
)
def test_patience_stops_exactly_patience_steps_after_the_last_improvement(
    patience, min_steps, tiebreak
):
    # The window opens at the first update (end of the warm-up); never before min_steps.
    # (The force motor and explicit Euler: a plateau this short search leaves and stalls on.)
    env = PendulumConfig(n_carts=1, steps=50, motor="force", integrator="euler")
    hp = DDPGConfig(
        max_steps=5000,
        patience_steps=patience,
        plateau_tiebreak=tiebreak,
        **{**SMALL, "min_steps": min_steps},
    )
    theta, omega = initial(1, 1)
    result = local_search(theta[0], omega[0], env, hp, seed=0)
    last, best = hp.warmup_steps, (-np.inf, -np.inf)
    for record in result.history:
        score = (record.greedy_fitness, record.greedy_return)
        if record.env_steps >= hp.warmup_steps and is_improvement(score, best, tiebreak):
            last, best = record.env_steps, score
    if tiebreak:  # the test must see an improvement after the first candidate
        assert last > hp.warmup_steps + 2 * env.steps
    assert result.stop_reason == "patience"
    assert result.env_steps == max(min_steps, last + patience)


def test_plateau_tiebreak_counts_return_progress_only_on_equal_fitness():
    assert is_improvement((0.2, -9.0), (0.1, 50.0), plateau_tiebreak=True)
    assert not is_improvement((0.1, 60.0), (0.2, 0.0), plateau_tiebreak=True)
    assert is_improvement((0.0, 3.0), (0.0, 2.0), plateau_tiebreak=True)
    assert not is_improvement((0.0, 3.0), (0.0, 2.0), plateau_tiebreak=False)
    assert not is_improvement((0.0, 2.0), (0.0, 2.0), plateau_tiebreak=True)


# A task without integrator energy pumping (semi-implicit Euler, an overdamped hinge): score
# steps with the rod deflected more than 15 degrees from hanging. That needs a sustained cart
# acceleration above g tan(15 deg) = 2.6 m/s^2, i.e. an Actor output below 0.17 or above
# 0.83; untrained sigmoid Actors stay near 0.5 and score 0. DDPG must learn to push.
LEARNING_ENV = PendulumConfig(
    n_carts=1,
    steps=200,
    upright_angle=2.88,
    motor="acceleration",
    motor_gain=2.0,
    hinge_friction=0.3,
    integrator="semi-implicit",
    termination_penalty=0.0,
)
LEARNING_THRESHOLD = 0.08  # a sustained full push scores 0.115 before the track ends


def test_learning_task_is_out_of_reach_for_untrained_policies():
    spec = actor_spec(1)
    rng = np.random.default_rng(11)
    thetas = np.stack([spec.initial(rng) for _ in range(64)])
    policy = lambda obs: forward_numpy(spec, thetas, obs)  # noqa: E731
    assert (evaluate(policy, LEARNING_ENV, 64).fitness == 0).all()
    for push, reachable in ((0.2, False), (0.5, False), (0.8, False), (0.0, True), (1.0, True)):
        constant = lambda obs, a=push: np.full((obs.shape[0], 1), a)  # noqa: E731
        assert (evaluate(constant, LEARNING_ENV).fitness[0] > LEARNING_THRESHOLD) == reachable


def test_ddpg_learns_a_task_untrained_policies_cannot_pass():
    hp = DDPGConfig(
        batch_size=128,
        buffer_size=10_000,
        warmup_steps=500,
        max_steps=2500,
        min_steps=0,
        patience_steps=10**6,
    )
    thetas, omegas = initial(1, 3)
    results = local_search_batch(thetas, omegas, LEARNING_ENV, hp, seeds=[0, 1, 2])
    for result in results:
        assert result.start_fitness == 0.0
        assert result.fitness >= LEARNING_THRESHOLD and result.improved


def test_eight_two_cart_agents_together_equal_each_alone_bit_for_bit():
    # 8 agents x 2 carts: the per-step action and noise arrays are long enough for vector
    # loops (the SIMD padding of lonlib.ddpg.streams and the act output must hold).
    env = PendulumConfig(n_carts=2, steps=60, initial_noise=0.02, upright_angle=2.9)
    hp = DDPGConfig(max_steps=260, patience_steps=10**6, **SMALL)
    thetas, omegas = initial(2, 8, seed=3)
    together = local_search_batch(thetas, omegas, env, hp, seeds=list(range(8)))
    for i in (0, 5):
        alone = local_search(thetas[i], omegas[i], env, hp, seed=i)
        np.testing.assert_array_equal(together[i].theta, alone.theta)
        returns = [h.episode_return for h in together[i].history]
        assert returns == [h.episode_return for h in alone.history]


def test_batch_sizes_that_break_batch_invariance_are_refused_for_several_agents():
    thetas, omegas = initial(1, 2)
    hp = DDPGConfig(**{**SMALL, "batch_size": 37})
    with pytest.raises(ValueError, match="batch_size must be a multiple of 8"):
        local_search_batch(thetas, omegas, PendulumConfig(n_carts=1), hp, seeds=[0, 1])
    alone = local_search(
        thetas[0],
        omegas[0],
        PendulumConfig(n_carts=1, steps=40),
        dataclasses.replace(hp, max_steps=300),
        0,
    )  # one agent alone may use any batch size
    assert alone.env_steps == 300


@pytest.mark.parametrize("device", ["meta", "cuda:99"])
def test_a_device_this_machine_lacks_is_refused_by_name(device):
    thetas, omegas = initial(1, 1)
    hp = DDPGConfig(**{**SMALL, "device": device})
    with pytest.raises(ValueError, match="device"):
        local_search(thetas[0], omegas[0], PendulumConfig(n_carts=1), hp, seed=0)


def test_start_noise_is_symmetric_and_within_its_level():
    env = PendulumConfig(n_carts=2, initial_noise=0.05)
    thetas, omegas = initial(2, 64)
    trainer = SlotTrainer(thetas, omegas, list(range(64)), env, DDPGConfig(**SMALL))
    offsets = trainer.sim.x - env.initial_positions()
    assert np.abs(offsets).max() <= 0.05 and offsets.min() < -0.02 and offsets.max() > 0.02
    angles = trainer.sim.phi - np.pi
    assert np.abs(angles).max() <= 0.05 and angles.min() < -0.02 and angles.max() > 0.02


def test_episode_losses_are_the_means_of_that_episodes_updates(monkeypatch):
    env = PendulumConfig(n_carts=1, steps=40)
    hp = DDPGConfig(max_steps=300, patience_steps=10**6, **SMALL)
    thetas, omegas = initial(1, 1)
    trainer = SlotTrainer(thetas, omegas, [4], env, hp)
    seen = []
    train = trainer.learner.train

    def recording(batch):
        losses = train(batch)
        seen.append((int(trainer.steps[0]), losses[0, 0].item()))
        return losses

    monkeypatch.setattr(trainer.learner, "train", recording)
    finished = []
    while trainer.busy.any():
        finished += trainer.step()
    ((_, result),) = finished
    start, checked = 0, 0
    for record in result.history:
        mine = [loss for step, loss in seen if start < step <= record.env_steps]
        if mine:
            assert record.critic_loss == pytest.approx(np.mean(mine), rel=1e-9)
            checked += 1
        else:
            assert np.isnan(record.critic_loss)
        start = record.env_steps
    assert checked >= 3
