"""Algorithm 2 semantics with a fast deterministic stand-in for DDPG."""

import numpy as np
import pytest

from lonlib.config import BasinHoppingConfig, PendulumConfig
from lonlib.ddpg.search_interface import ddpg_local_search
from lonlib.search.algorithm import (
    LocalOptimum,
    RunState,
    basin_hopping,
    basin_hopping_steps,
    trial_seeds,
)
from lonlib.task.policy import actor_spec, critic_spec
from tests.conftest import tiny_ddpg

START = (np.zeros(6, dtype=np.float32), np.zeros(4, dtype=np.float32))


def scripted(fitnesses):
    """A local search returning the given fitness sequence and recording its inputs."""
    calls = []

    def search(theta, omega, seed):
        calls.append((theta.copy(), omega.copy(), seed))
        f = fitnesses[len(calls) - 1]
        return LocalOptimum(f, theta + len(calls), omega - len(calls), env_steps=10)

    return search, calls


def test_equal_fitness_is_accepted_and_counter_resets():
    search, _ = scripted([0.3, 0.2, 0.3, 0.1, 0.1, 0.5, 0.0, 0.0])
    state = basin_hopping(search, START, BasinHoppingConfig(tolerance=2), run_seed=0)
    assert [t.accepted for t in state.trials] == [True, False, True, False, False]
    assert state.end_reason == "tolerance"
    # 0.1, 0.1 after the equal 0.3 were two consecutive failures: exactly T ends the run
    assert state.incumbent.fitness == 0.3 and state.incumbent_index == 2
    assert [t.parent for t in state.trials] == [-1, 0, 0, 2, 2]


def test_a_better_optimum_is_accepted_and_a_worse_one_is_not():
    search, _ = scripted([0.3, 0.31, 0.2999])
    config = BasinHoppingConfig(tolerance=1)
    state = basin_hopping(search, START, config, run_seed=0)
    assert [t.accepted for t in state.trials] == [True, True, False]
    assert state.incumbent_index == 1 and state.incumbent.fitness == 0.31


def test_the_next_perturbation_starts_from_the_incumbent_not_the_last_trial():
    search, calls = scripted([0.5, 0.1, 0.6, 0.6, 0.0, 0.0])
    basin_hopping(search, START, BasinHoppingConfig(tolerance=2), run_seed=3)
    # trial i returns its input + (i + 1): incumbents are trial 0 (+1), 2 (+4), 3 (+8)
    for (theta, _, _), want in zip(calls[1:], [1, 1, 4, 8, 8], strict=True):
        np.testing.assert_allclose(theta, START[0] + want, atol=5e-4)


def test_trials_record_the_start_fitness_improvement_and_stop_reason():
    def search(theta, omega, seed):
        return LocalOptimum(0.4, theta, omega, 7, start_fitness=0.25, stop_reason="patience")

    state = basin_hopping(search, START, BasinHoppingConfig(tolerance=1), run_seed=0)
    trial = state.trials[0]
    assert (trial.start_fitness, trial.improved, trial.stop_reason) == (0.25, True, "patience")

    def no_better(theta, omega, seed):
        return LocalOptimum(0.25, theta, omega, 7, start_fitness=0.25, stop_reason="budget")

    state = basin_hopping(no_better, START, BasinHoppingConfig(tolerance=1), run_seed=0)
    assert state.trials[0].improved is False and state.trials[0].start_fitness == 0.25


def test_perturbation_and_local_search_draw_from_independent_streams():
    search, calls = scripted([0.5, 0.4, 0.4])
    p = 1e-3
    basin_hopping(search, START, BasinHoppingConfig(perturbation=p, tolerance=2), run_seed=4)
    seeds = [trial_seeds(4, i) for i in range(3)]
    assert [seed for _, _, seed in calls] == [s.local_search for s in seeds]
    assert len({s.perturbation for s in seeds} | {s.local_search for s in seeds}) == 6
    for (theta, _, seed), s in zip(calls[1:], seeds[1:], strict=True):
        delta = theta.astype(np.float64) - (START[0] + 1)
        same_stream = np.random.default_rng(seed).uniform(-p, p, size=delta.shape)
        own_stream = np.random.default_rng(s.perturbation).uniform(-p, p, size=delta.shape)
        np.testing.assert_allclose(delta, own_stream, atol=1e-6)
        assert not np.allclose(delta, same_stream, atol=1e-6)


def test_exactly_tolerance_failures_end_a_run():
    search, calls = scripted([0.5] + [0.1] * 10)
    state = basin_hopping(search, START, BasinHoppingConfig(tolerance=4), run_seed=0)
    assert len(calls) == 5 and state.end_reason == "tolerance"


def test_budget_ends_a_run_with_its_reason():
    search, calls = scripted([0.1 * i for i in range(20)])  # always improving
    config = BasinHoppingConfig(tolerance=3, max_local_searches=7)
    state = basin_hopping(search, START, config, run_seed=0)
    assert len(calls) == 7 and state.end_reason == "budget"
    assert all(t.accepted for t in state.trials)


def test_perturbation_touches_every_parameter_within_p():
    search, calls = scripted([0.5, 0.4, 0.4, 0.4])
    p = 1e-3
    basin_hopping(search, START, BasinHoppingConfig(perturbation=p, tolerance=3), run_seed=1)
    incumbent_theta, incumbent_omega = START[0] + 1, START[1] - 1  # first optimum
    for theta, omega, _ in calls[1:]:
        for new, old in ((theta, incumbent_theta), (omega, incumbent_omega)):
            delta = new.astype(np.float64) - old
            assert (np.abs(delta) <= p * (1 + 1e-3)).all()
            assert (delta != 0).all()  # every parameter moved


def test_resuming_from_a_stored_state_continues_identically():
    fit = [0.2, 0.1, 0.3, 0.3, 0.1, 0.1, 0.1]
    by_seed = {trial_seeds(9, i).local_search: f for i, f in enumerate(fit)}

    def pure(theta, omega, seed):  # a function of its inputs only, like a seeded DDPG
        return LocalOptimum(by_seed[seed], theta + 1, omega - 1)

    config = BasinHoppingConfig(tolerance=3)
    full = basin_hopping(pure, START, config, run_seed=9)
    steps = basin_hopping_steps(pure, START, config, run_seed=9)
    for _ in range(3):
        state, _, _ = next(steps)
    stored = RunState(list(state.trials), state.incumbent, state.incumbent_index, state.failures)
    resumed = list(basin_hopping_steps(pure, START, config, 9, state=stored))[-1][0]
    strip = lambda trials: [(t.index, t.parent, t.fitness, t.accepted) for t in trials]  # noqa: E731
    assert strip(resumed.trials) == strip(full.trials)
    assert resumed.end_reason == full.end_reason == "tolerance"
    np.testing.assert_array_equal(resumed.incumbent.theta, full.incumbent.theta)


@pytest.mark.parametrize(
    ("field", "value"),
    [("perturbation", 0.0), ("perturbation", -1e-4), ("tolerance", 0), ("max_local_searches", 0)],
)
def test_bad_configuration_is_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        BasinHoppingConfig(**{field: value})


def test_ddpg_is_the_default_local_search():
    env = PendulumConfig(n_carts=1, steps=40)
    hp = tiny_ddpg(max_steps=120, patience_steps=10**6)
    rng = np.random.default_rng(0)
    start = (actor_spec(1).initial(rng), critic_spec(1).initial(rng))
    config = BasinHoppingConfig(tolerance=1, max_local_searches=3)
    state = basin_hopping(ddpg_local_search(env, hp), start, config, run_seed=0)
    assert 1 < len(state.trials) <= 3
    assert state.incumbent.theta.shape == (actor_spec(1).n_params,)


def test_the_step_and_the_acceptance_are_pluggable_like_scipys_basinhopping():
    search, calls = scripted([0.5, 0.4, 0.2, 0.3])
    steps = []

    def no_noise(theta, omega, p, rng):
        steps.append(p)
        return theta.copy(), omega.copy()

    state = basin_hopping(
        search,
        START,
        BasinHoppingConfig(perturbation=0.25, tolerance=2, max_local_searches=4),
        run_seed=0,
        take_step=no_noise,
        accept_test=lambda f_new, f_best: f_new >= f_best - 0.15,  # a little worse is fine
    )
    assert [t.accepted for t in state.trials] == [True, True, False, True]
    assert steps == [0.25, 0.25, 0.25] and state.end_reason == "budget"
    # no noise: each start is exactly the incumbent's parameters (trial i returns input + i+1)
    np.testing.assert_array_equal(calls[1][0], START[0] + 1)
    np.testing.assert_array_equal(calls[3][0], START[0] + 3)


def test_each_trial_records_the_seconds_of_its_local_search(monkeypatch):
    import types

    import lonlib.search.algorithm as algorithm

    ticks = iter(np.arange(100) * 1.5)
    monkeypatch.setattr(algorithm, "time", types.SimpleNamespace(perf_counter=lambda: next(ticks)))
    search, _ = scripted([0.3, 0.2, 0.1])
    state = basin_hopping(search, START, BasinHoppingConfig(tolerance=2), run_seed=0)
    assert [t.seconds for t in state.trials] == [1.5, 1.5, 1.5]
