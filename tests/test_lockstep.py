"""The lockstep executor: the same trials as the serial executor, whatever the batch."""

import dataclasses
import hashlib

import numpy as np
import pandas as pd
import pytest

from lonlib.ddpg import DDPGConfig
from lonlib.experiment import ExperimentConfig, run_experiment
from lonlib.pendulum import PendulumConfig
from lonlib.store import read_experiment_trials

# Searches stop by patience at different times, so slots are refilled while others are in
# their warm-up or training: a run's trials must still not depend on its neighbours.
CONFIG = ExperimentConfig(
    name="lockstep",
    perturbations=(1e-3, 1e-4),
    runs=4,
    tolerance=2,
    max_local_searches=4,
    env=PendulumConfig(
        n_carts=1,
        steps=40,
        upright_angle=2.9,
        motor="acceleration",
        motor_gain=2.0,
        initial_noise=0.02,  # refills draw start noise from the new search's streams
    ),
    ddpg=DDPGConfig(
        batch_size=32,
        buffer_size=500,
        warmup_steps=50,
        max_steps=240,
        min_steps=0,
        patience_steps=60,
    ),
)
TIME_COLUMNS = ["seconds"]


def stored(folder):
    """Trials (without timings) and a digest of every stored optimum and history."""
    trials = read_experiment_trials(folder).drop(columns=TIME_COLUMNS)
    digest = {}
    for path in sorted(folder.glob("p=*/run_*/*")):
        if path.suffix == ".npz":
            with np.load(path) as data:
                digest[str(path.relative_to(folder))] = hashlib.sha256(
                    b"".join(data[k].tobytes() for k in sorted(data.files))
                ).hexdigest()
        elif path.name.startswith("history_"):
            history = pd.read_parquet(path).drop(columns=["seconds"])
            digest[str(path.relative_to(folder))] = history
    return trials, digest


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    folder = tmp_path_factory.mktemp("serial")
    run_experiment(CONFIG, folder, progress=False, executor="serial")
    return stored(folder)


@pytest.mark.parametrize("slots", [3, 8])  # one slot: the resume test below
def test_lockstep_trials_equal_the_serial_executors_bit_for_bit(serial, tmp_path, slots):
    run_experiment(CONFIG, tmp_path, progress=False, executor="lockstep", slots=slots)
    trials, digest = stored(tmp_path)
    want_trials, want_digest = serial
    assert len(trials) > 2 * CONFIG.runs  # runs went past their first search
    assert trials["stop_reason"].eq("patience").any()  # searches ended at different times
    pd.testing.assert_frame_equal(trials, want_trials)
    assert digest.keys() == want_digest.keys()
    for key, value in digest.items():
        if isinstance(value, pd.DataFrame):
            pd.testing.assert_frame_equal(value, want_digest[key], check_exact=True)
        else:
            assert value == want_digest[key], key


def test_a_killed_lockstep_experiment_resumes_to_the_same_trials(serial, tmp_path, monkeypatch):
    import lonlib.lockstep

    stored_steps = []
    save = lonlib.lockstep.save_step

    def save_then_die(*args, **kwargs):
        save(*args, **kwargs)
        stored_steps.append(args[1:3])
        if len(stored_steps) == 5:
            raise KeyboardInterrupt  # killed with searches of other runs in flight

    monkeypatch.setattr(lonlib.lockstep, "save_step", save_then_die)
    with pytest.raises(KeyboardInterrupt):
        run_experiment(CONFIG, tmp_path, progress=False, executor="lockstep", slots=4)
    monkeypatch.undo()
    assert len(read_experiment_trials(tmp_path)) == 5
    # every run's lock was released: a second session resumes at once, with other slots
    run_experiment(CONFIG, tmp_path, progress=False, executor="lockstep", slots=1)
    trials, digest = stored(tmp_path)
    pd.testing.assert_frame_equal(trials, serial[0])
    assert digest.keys() == serial[1].keys()


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"executor": "lockstep", "scheduler": "dask-local"}, "does not use one"),
        ({"executor": "dask"}, "needs a scheduler"),
        ({"executor": "threads"}, "executor must be one of"),
        ({"executor": "lockstep", "slots": 0}, "slots must be"),
        ({"executor": "lockstep", "slots": 2, "config": {"batch_size": 36}}, "multiple of 8"),
        ({"executor": "lockstep", "config": {"update": "autograd"}}, "update='lean'"),
    ],
)
def test_bad_executor_settings_are_refused_before_any_compute(tmp_path, changes, message):
    changes = dict(changes)
    ddpg = dataclasses.replace(CONFIG.ddpg, **changes.pop("config", {}))
    config = dataclasses.replace(CONFIG, ddpg=ddpg)
    with pytest.raises(ValueError, match=message):
        run_experiment(config, tmp_path / "out", progress=False, **changes)
    assert not (tmp_path / "out").exists()


def test_executor_and_slots_are_not_part_of_what_must_match_to_resume(tmp_path):
    config = dataclasses.replace(CONFIG, runs=1, perturbations=(1e-3,), max_local_searches=1)
    run_experiment(config, tmp_path, progress=False, executor="serial")
    lockstep = dataclasses.replace(config, executor="lockstep", slots=2, runs=2)
    trials = run_experiment(lockstep, tmp_path, progress=False)
    assert sorted(trials["run"].unique()) == [0, 1]


def test_cli_runs_the_lockstep_executor(tmp_path, capsys):
    from lonlib.cli import main

    path = tmp_path / "tiny.yaml"
    path.write_text(
        "name: tiny\nperturbations: [1.0e-3]\nruns: 2\ntolerance: 1\nmax_local_searches: 2\n"
        "env: {n_carts: 1, steps: 40}\n"
        "ddpg: {batch_size: 16, buffer_size: 200, warmup_steps: 30, max_steps: 60, min_steps: 0}\n"
    )
    main(
        [
            "run",
            str(path),
            "--executor",
            "lockstep",
            "--slots",
            "2",
            "--device",
            "cpu",
            "--out",
            str(tmp_path / "out"),
            "--quiet",
        ]
    )
    assert "local searches stored" in capsys.readouterr().out
    assert len(read_experiment_trials(tmp_path / "out")) >= 2


def test_lockstep_in_two_processes_gives_the_serial_trials(serial, tmp_path):
    run_experiment(CONFIG, tmp_path, progress=False, executor="lockstep", slots=3, workers=2)
    trials, digest = stored(tmp_path)
    pd.testing.assert_frame_equal(trials, serial[0])
    assert digest.keys() == serial[1].keys()
