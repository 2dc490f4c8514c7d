"""Rerun recordings read back with the expected entities and number of frames."""

import subprocess
import sys
from pathlib import Path

import numpy as np

from lonlib.analysis.recordings import (
    APP_ID,
    record,
    recorded_entities,
    recording_id,
    recording_name,
    recording_properties,
    scene,
    scene_bounds,
)
from lonlib.config import PendulumConfig
from lonlib.task.policy import actor_spec
from lonlib.task.rollout import run_actors


def test_recording_reads_back_with_entities_and_frames(tmp_path):
    config = PendulumConfig(n_carts=2, steps=120)
    theta = actor_spec(2).initial(np.random.default_rng(0))
    theta[-2:] = 0.0  # output bias 0: the policy still acts from its sensors
    path = tmp_path / recording_name(1e-4, 3, 0.25)
    assert path.name == "optimum_p=0.0001_run=3_f=0.250.rrd"
    episode = record(theta, config, path, properties={"p": 1e-4, "run": 3, "index": 7})
    frames = int(episode.end_step[0])
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
    stores = subprocess.run(
        [str(rerun), "rrd", "print", str(path)], capture_output=True, text=True
    ).stdout
    # The layout travels in the file (a blueprint store), under a plain application id.
    assert "Blueprint" in stores and f'"{APP_ID}"' in stores
    assert f'"{recording_id(path)}"' in stores


def test_recording_ids_are_plain_entry_names():
    assert APP_ID.replace("_", "").isalnum()
    assert recording_id("x/best_optimum_p=0.0001_run=3_f=0.720.rrd") == (
        "best_optimum_p_0_0001_run_3_f_0_720"
    )


def test_scene_hangs_hanging_rods_in_rerun_y_down_coordinates():
    """rerun's 2-D views draw y downwards: the scene negates heights, so a rod at the start
    (hanging) has its tip below the hinge on screen, an upright rod above it, carts sit
    above the track, and the view's bounds hold the track and every rod position."""
    config = PendulumConfig(n_carts=2, steps=50)
    result = run_actors(actor_spec(2).initial(np.random.default_rng(1)), config, trace=True)
    start = result.trace.row(0, int(result.end_step[0]))
    end = config.track_half_length - config.cart_width / 2
    x = np.vstack([start.x[:1], [[-end, end]], [[-end, end]]])
    phi = np.vstack([start.phi[:1], [[0.0, 0.0]], [[np.pi, np.pi]]])
    drawn = scene(x, phi, config)
    hinge, tip = drawn.rods[:, :, 0], drawn.rods[:, :, 1]
    rod = 2 * config.pole_half_length
    assert np.all(tip[0, :, 1] - hinge[0, :, 1] > 0.99 * rod)  # hanging at the start
    assert np.allclose(tip[1, :, 1] - hinge[1, :, 1], -rod)  # upright: up on screen
    assert np.allclose(tip[2, :, 0], hinge[2, :, 0])
    assert np.all(drawn.cart_centres[..., 1] < 0)  # above the track line y = 0
    assert np.all(drawn.track[1:, 1, 1] < 0)  # the end posts point up
    assert np.allclose(drawn.tether[:, 0], drawn.cart_centres[:, :2])
    (x_low, x_high), (y_low, y_high) = scene_bounds(config)
    points = np.concatenate([drawn.rods.reshape(-1, 2), drawn.track.reshape(-1, 2)])
    assert np.all((points[:, 0] > x_low) & (points[:, 0] < x_high))
    assert np.all((points[:, 1] > y_low) & (points[:, 1] < y_high))


def test_a_recording_carries_and_replays_its_scored_episode(tmp_path):
    config = PendulumConfig(n_carts=1, steps=200)
    theta = actor_spec(1).initial(np.random.default_rng(5))
    path = tmp_path / "x.rrd"
    episode = record(theta, config, path, properties={"p": 1e-3, "run": 2, "index": 4})
    scored = run_actors(theta, config)
    props = recording_properties(path)
    assert props["fitness"] == scored.fitness[0] == episode.fitness[0]
    assert props["end_step"] == scored.end_step[0] == episode.trace.fitness.shape[0]
    assert (props["p"], props["run"], props["index"]) == (1e-3, 2, 4)
    assert props["fitness_all"] == scored.fitness_all[0]
    assert episode.trace.fitness[-1, 0] == scored.fitness[0]


def test_recording_names_follow_one_scheme():
    name = recording_name(1e-4, 3, 0.372, role="label-best", behaviour="crash")
    assert name == "label-best_crash_optimum_p=0.0001_run=3_f=0.372.rrd"
    assert recording_name(1e-3, 1, 0.5, role="best") == "best_optimum_p=0.001_run=1_f=0.500.rrd"
