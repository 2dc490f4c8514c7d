"""The worked examples' behaviour descriptors (:mod:`lonlib.task.gymnasium_descriptors`) on
hand-made episodes at each side of each threshold: the committed labels rest on them."""

import numpy as np
import pytest

from lonlib.task.gymnasium_behaviour import EpisodeTrace
from lonlib.task.gymnasium_descriptors import (
    MOUNTAIN_CAR_GOAL,
    STAY_PUT_FUEL,
    UPRIGHT_COS,
    mountain_car,
    pendulum_v1,
)
from lonlib.task.gymnasium_task import Episode

UP = np.radians(20.0)  # the upright threshold's angle: cos(UP) is UPRIGHT_COS
DOWN = np.pi


def trace(observations, actions=None) -> EpisodeTrace:
    """An episode of the given observations (the first one reset's), actions and zero
    rewards."""
    observations = np.asarray(observations, dtype=np.float64)
    steps = len(observations) - 1
    actions = np.zeros((steps, 1)) if actions is None else np.asarray(actions, dtype=np.float64)
    return EpisodeTrace(observations, actions, np.zeros(steps), Episode(0.0, steps, False, 0.0))


def pendulum(angles) -> dict:
    """Pendulum-v1's descriptor of the pendulum at ``angles`` (0 upright), reset's first."""
    angles = np.asarray(angles, dtype=np.float64)
    return pendulum_v1(trace(np.stack([np.cos(angles), np.sin(angles), 0 * angles], axis=1)))


def test_pendulum_v1_upright_is_within_20_degrees_inclusive():
    assert float(np.cos(UP)) == UPRIGHT_COS
    held = pendulum([DOWN] * 7 + [UP, -UP])  # 8 steps: the last quarter (2) at exactly 20°
    assert held["label"] == "swings up and holds"
    assert (held["upright_share"], held["held_end"]) == (2 / 8, 1.0)
    beyond = pendulum([DOWN] * 7 + [UP, np.radians(20.01)])
    assert beyond["label"] == "swings" and beyond["held_end"] == 0.5


def test_pendulum_v1_reads_the_steps_not_the_reset_and_the_last_quarter():
    hangs = pendulum([0.0] + [DOWN] * 8)  # upright at reset only
    assert hangs["label"] == "hangs" and hangs["upright_share"] == 0.0
    assert pendulum([DOWN] * 6 + [0.0, 0.0, DOWN])["label"] == "swings"  # not to the end
    assert pendulum([DOWN] * 5 + [0.0] * 4)["label"] == "swings up and holds"
    # three steps: the last quarter is at least the last step
    short = pendulum([DOWN, DOWN, DOWN, 0.0])
    assert short["label"] == "swings up and holds" and short["held_end"] == 1.0


@pytest.mark.parametrize(
    ("turns", "label"), [(2.01, "spins"), (-2.01, "spins"), (1.99, "swings"), (-1.99, "swings")]
)
def test_pendulum_v1_spins_from_two_net_revolutions_either_way(turns, label):
    angles = DOWN + np.linspace(0.0, 2 * np.pi * turns, 65)  # 64 steps, ~0.2 rad each
    described = pendulum(angles)
    assert described["label"] == label and described["turns"] == pytest.approx(turns)


def test_pendulum_v1_holding_at_the_end_outranks_spinning():
    spin = DOWN + np.linspace(0.0, 5 * np.pi, 49)  # 2.5 turns, ending upright (6 pi)
    described = pendulum(np.concatenate([spin, [6 * np.pi] * 16]))  # then held: 16 of 64
    assert described["turns"] == pytest.approx(2.5)
    assert described["label"] == "swings up and holds"


def car(positions, pushes) -> dict:
    """MountainCarContinuous-v0's descriptor of the car at ``positions`` (reset's first)
    pushed by ``pushes``."""
    positions = np.asarray(positions, dtype=np.float64)
    observations = np.stack([positions, np.zeros_like(positions)], axis=1)
    return mountain_car(trace(observations, np.asarray(pushes, dtype=np.float64)[:, None]))


def test_mountain_car_reaches_the_goal_at_0_45_inclusive():
    assert MOUNTAIN_CAR_GOAL == 0.45
    at = car([-0.5, 0.0, 0.45], [1.0, 1.0])
    assert at["label"] == "reaches the goal" and at["max_position"] == 0.45
    assert car([-0.5, 0.0, 0.4499], [1.0, 1.0])["label"] == "pushes without reaching"
    assert car([-0.5, 0.45, 0.2], [0.0, 0.0])["label"] == "reaches the goal"  # fuel or not


def test_mountain_car_stays_put_below_one_unit_of_fuel():
    assert STAY_PUT_FUEL == 1.0
    below = car([-0.5, -0.49, -0.48, -0.49], [0.5, -0.5, 0.5])  # fuel 0.75; min at reset
    assert below["label"] == "stays put" and below["fuel"] == 0.75
    assert below["position_range"] == pytest.approx(0.02) and below["max_position"] == -0.48
    at = car([-0.5, -0.49, -0.48, -0.47, -0.6], [0.5, -0.5, 0.5, -0.5])  # fuel exactly 1
    assert at["label"] == "pushes without reaching" and at["fuel"] == 1.0
    assert at["position_range"] == pytest.approx(0.13)
