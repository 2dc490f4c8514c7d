"""Behaviour descriptors for the worked examples' Gymnasium tasks (``task.descriptor``), and
models for a user's own: each a function of one scored greedy episode
(:class:`lonlib.task.gymnasium_behaviour.EpisodeTrace`) returning named numbers and a label.

* :func:`pendulum_v1` (``lonlib.task.gymnasium_descriptors:pendulum_v1``): Pendulum-v1's
  observations are ``(cos angle, sin angle, angular velocity)`` with the angle 0 upright.
* :func:`mountain_car` (``lonlib.task.gymnasium_descriptors:mountain_car``):
  MountainCarContinuous-v0's are ``(position, velocity)``, the goal at position 0.45.
"""

from __future__ import annotations

import numpy as np

from lonlib.task.gymnasium_behaviour import EpisodeTrace

UPRIGHT_COS = float(np.cos(np.radians(20.0)))  # "up": within 20 degrees of upright
MOUNTAIN_CAR_GOAL = 0.45
STAY_PUT_FUEL = 1.0  # sum of squared actions (a full push for one step costs 1)


def pendulum_v1(trace: EpisodeTrace) -> dict[str, float | str]:
    """Pendulum-v1: ``upright_share`` (steps within 20 degrees of upright), ``held_end``
    (share of the last quarter's steps upright), ``turns`` (net revolutions) and a label:
    ``swings up and holds`` (up for the whole last quarter), ``spins`` (two or more net
    revolutions), ``swings`` (up at times), ``hangs`` (never up)."""
    cos, sin = trace.observations[:, 0], trace.observations[:, 1]
    up = cos[1:] >= UPRIGHT_COS
    angle = np.unwrap(np.arctan2(sin, cos))
    turns = float((angle[-1] - angle[0]) / (2 * np.pi))
    last = up[-max(1, len(up) // 4) :]
    if last.all():
        label = "swings up and holds"
    elif abs(turns) >= 2:
        label = "spins"
    elif up.any():
        label = "swings"
    else:
        label = "hangs"
    return {
        "upright_share": float(up.mean()),
        "held_end": float(last.mean()),
        "turns": turns,
        "label": label,
    }


def mountain_car(trace: EpisodeTrace) -> dict[str, float | str]:
    """MountainCarContinuous-v0: ``max_position``, ``position_range`` (how far it rocked),
    ``fuel`` (sum of squared actions, what the reward charges) and a label: ``reaches the
    goal``, ``stays put`` (fuel below 1: it coasts where the start left it, the deceptive
    optimum), ``pushes without reaching`` (otherwise)."""
    position = trace.observations[:, 0]
    fuel = float(np.sum(trace.actions**2))
    if position.max() >= MOUNTAIN_CAR_GOAL:
        label = "reaches the goal"
    elif fuel < STAY_PUT_FUEL:
        label = "stays put"
    else:
        label = "pushes without reaching"
    return {
        "max_position": float(position.max()),
        "position_range": float(position.max() - position.min()),
        "fuel": fuel,
        "label": label,
    }


__all__ = ["mountain_car", "pendulum_v1"]
