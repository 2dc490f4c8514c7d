"""The lockstep executor: the same trials as the serial executor, whatever the batch."""

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
        n_carts=1, steps=40, upright_angle=2.9, motor="acceleration", motor_gain=2.0
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


@pytest.mark.parametrize("slots", [1, 3, 8])
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
