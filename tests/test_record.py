"""Rerun recordings read back with the expected entities and number of frames."""

import subprocess
import sys
from pathlib import Path

import numpy as np

from lonlib.nets import actor_spec
from lonlib.pendulum import PendulumConfig
from lonlib.record import record, recorded_entities, recording_name, rollout


def test_recording_reads_back_with_entities_and_frames(tmp_path):
    config = PendulumConfig(n_carts=2, steps=120)
    theta = actor_spec(2).initial(np.random.default_rng(0))
    theta[-2:] = 0.0  # output bias 0: the policy still acts from its sensors
    path = tmp_path / recording_name(1e-4, 3, 0.25)
    assert path.name == "optimum_p=0.0001_run=3_f=0.250.rrd"
    episode = record(theta, config, path)
    frames = len(episode.fitness)
    counts = recorded_entities(path)
    for entity in (
        "/world/carts",
        "/world/rods",
        "/world/tether",
        "/sensors/cart_0",
        "/sensors/cart_1",
        "/actions",
        "/upright",
        "/fitness",
    ):
        assert counts[entity] == frames, entity
    assert counts["/world/track"] == 0  # static
    rerun = Path(sys.executable).with_name("rerun")
    verify = subprocess.run(
        [str(rerun), "rrd", "verify", str(path)], capture_output=True, text=True
    )
    assert verify.returncode == 0, verify.stderr


def test_rollout_matches_the_fitness_evaluation():
    from lonlib.nets import forward_numpy
    from lonlib.pendulum import evaluate

    config = PendulumConfig(n_carts=1, steps=200)
    theta = actor_spec(1).initial(np.random.default_rng(5))
    episode = rollout(theta, config)
    direct = evaluate(lambda o: forward_numpy(actor_spec(1), theta, o), config)
    assert episode.fitness[-1] == direct.fitness[0]
    assert len(episode.fitness) == direct.steps[0]
    assert episode.sensors.shape == (len(episode.fitness), 10)
