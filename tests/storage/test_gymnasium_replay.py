"""A stored optimum replays through gymnasium.make exactly (issue 48, item 4): float64
observations and the defined forward pass give the stored fitness bit for bit."""

from pathlib import Path

import gymnasium
import numpy as np
import pytest

import lonlib
from lonlib.cli import main as cli_main
from lonlib.storage import load_policy, read_experiment_trials
from lonlib.storage.policies import gymnasium_fitness

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("folder", ["data/reference", "data/one-cart"])
def test_stored_optima_replay_their_fitness_through_gymnasium_make(folder):
    trials = read_experiment_trials(ROOT / folder)
    accepted = trials[trials.accepted].sort_values("fitness")
    for row in (accepted.iloc[-1], accepted.iloc[len(accepted) // 2]):  # the best and a median
        policy = load_policy(ROOT / folder, row["p"], int(row["run"]), int(row["index"]))
        assert policy.fitness == row["fitness"]
        assert gymnasium_fitness(policy) == policy.fitness


def test_float32_observations_are_the_default_and_float64_the_exact_sensors():
    default = gymnasium.make(lonlib.ENV_ID)
    exact = gymnasium.make(lonlib.ENV_ID, observation_dtype="float64")
    first, _ = default.reset(seed=0)
    second, _ = exact.reset(seed=0)
    assert first.dtype == np.float32 and default.observation_space.dtype == np.float32
    assert second.dtype == np.float64 and exact.observation_space.dtype == np.float64
    action = np.array([0.9, 0.8])
    for _ in range(10):
        first = default.step(action)[0]
        second = exact.step(action)[0]
    assert np.array_equal(first, second.astype(np.float32))
    assert not np.array_equal(first.astype(np.float64), second)  # float32 rounds the sensors


def test_a_bad_observation_dtype_is_refused_by_name():
    with pytest.raises(ValueError, match="observation_dtype must be one of"):
        gymnasium.make(lonlib.ENV_ID, observation_dtype="float16")


def test_an_optimum_not_stored_is_refused_naming_its_file():
    with pytest.raises(ValueError, match="optimum_0999.npz: no stored Actor"):
        load_policy(ROOT / "data/reference", 1e-4, 0, 999)


def test_verify_gymnasium_reports_and_fails_on_a_mismatch(monkeypatch, capsys):
    import lonlib.storage.policies as policies

    monkeypatch.setattr(policies, "gymnasium_mismatches", lambda root: (3, ["p=1 run 0: off"]))
    with pytest.raises(SystemExit) as failed:
        cli_main(["verify", str(ROOT / "data/one-cart"), "--gymnasium", "--no-recordings"])
    assert failed.value.code == 1
    out = capsys.readouterr().out
    assert "[gymnasium] p=1 run 0: off" in out
    assert "gymnasium: 2 of 3 accepted optima" in out
