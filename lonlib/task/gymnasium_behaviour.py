"""Optional behaviour descriptors of a Gymnasium task's optima (``task.descriptor``).

The pendulums describe every optimum by what its scored episode did (:mod:`lonlib.task.behaviour`);
a Gymnasium task can too, by a function of the user's, named ``module:function`` in the
task's configuration. It is called with the optimum's scored greedy episode, step by step
(:class:`EpisodeTrace`: the environment's own observations, actions and rewards, recorded by a
wrapper around the episode that scores the fitness), and returns a mapping of named numbers
and optionally a ``label`` (text). They are stored with the trial as ``b_<name>`` columns and
``label`` (:func:`describe_optimum`), replayed by ``lonlib verify``, and the analysis groups
optima by the label (Figs. 4 and 5 coloured by it, the behaviours table, the behavioural LON).

A descriptor must be a deterministic function of the episode (it is replayed); a wrong
return (not a mapping, a name that is not an identifier, a value that is not a finite number,
a label that is not text) raises ValueError naming ``task.descriptor`` and the entry.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import gymnasium
import numpy as np

from lonlib.task.gymnasium_task import Episode, GymnasiumTask

PREFIX = "b_"  # the trials table's behaviour columns, as the pendulums'
NAME = re.compile(r"[A-Za-z_]\w*")


@dataclass(frozen=True)
class EpisodeTrace:
    """One scored greedy episode of an Actor, step by step (what a descriptor reads)."""

    observations: np.ndarray
    """``[T + 1, o]``: the environment's observations (not scaled), from ``reset`` on."""
    actions: np.ndarray
    """``[T, a]``: the actions the environment received (in its Box bounds)."""
    rewards: np.ndarray
    """``[T]``: the rewards."""
    episode: Episode
    """Its return, length, end and fitness (the stored fitness)."""


class _Recorder(gymnasium.Wrapper):  # type: ignore[type-arg]
    """Passes every call through and keeps the raw observations, actions and rewards."""

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self.observations: list[np.ndarray] = []
        self.actions: list[np.ndarray] = []
        self.rewards: list[float] = []

    def reset(self, **kwargs: Any) -> Any:
        observation, info = self.env.reset(**kwargs)
        self.observations.append(np.array(observation, dtype=np.float64))
        return observation, info

    def step(self, action: Any) -> Any:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.actions.append(np.array(action, dtype=np.float64))
        self.observations.append(np.array(observation, dtype=np.float64))
        self.rewards.append(float(reward))
        return observation, reward, terminated, truncated, info


def trace_episode(task: GymnasiumTask, theta: np.ndarray, where: str) -> EpisodeTrace:
    """The greedy episode that scores ``theta`` (:meth:`GymnasiumTask.greedy_episode`),
    recorded step by step."""
    recorder = _Recorder(task.env)
    episode = task.greedy_episode(theta, where, env=recorder)
    return EpisodeTrace(
        observations=np.stack(recorder.observations),
        actions=np.stack(recorder.actions),
        rewards=np.array(recorder.rewards),
        episode=episode,
    )


def describe_optimum(
    task: GymnasiumTask, theta: np.ndarray, where: str = "behaviour descriptor"
) -> dict[str, Any]:
    """The stored behaviour of the Actor ``theta`` under the task's descriptor: ``b_<name>``
    floats and, if the descriptor gives one, ``label``; empty without a descriptor."""
    if not task.config.descriptor:
        return {}
    columns = _described(task, trace_episode(task, theta, where))
    names = sorted(columns)
    if task.descriptor_names is None:
        task.descriptor_names = names
    first = task.descriptor_names
    if names != first:  # a stored row must keep its columns (its digest covers them)
        raise ValueError(
            f"task.descriptor ({task.config.descriptor}) must return the same names for "
            f"every optimum: {first} before, now {names}"
        )
    return columns


def check_descriptor(task: GymnasiumTask) -> list[str]:
    """The columns (sorted ``b_<name>`` and ``label``) the task's descriptor gives a short
    trace, the greedy episode of a random Actor of the task's shape: what a run checks before
    any compute, so that a descriptor that raises or returns what it may not is one line
    naming ``task.descriptor`` then, not after the first local search. Empty without a
    descriptor. The task's :attr:`~GymnasiumTask.descriptor_names` are left to its optima."""
    if not task.config.descriptor:
        return []
    theta = task.actor_spec.initial(np.random.default_rng(0))
    where = "task.descriptor check, a random Actor's greedy episode"
    return sorted(_described(task, trace_episode(task, theta, where)))


def behaviour_names(columns: Iterable[str]) -> list[str]:
    """The behaviour columns among a trials table's ``columns`` (or a trial's behaviour
    keys): ``b_*`` and ``label``, sorted."""
    return sorted(name for name in columns if name.startswith(PREFIX) or name == "label")


def _described(task: GymnasiumTask, trace: EpisodeTrace) -> dict[str, Any]:
    """The task's descriptor of ``trace`` as checked columns (its error one line)."""
    try:
        described = task.descriptor(trace)
    except Exception as error:  # the user's code: one line naming it
        raise ValueError(
            f"task.descriptor ({task.config.descriptor}) raised {type(error).__name__}: {error}"
        ) from None
    return behaviour_columns(described, task.config.descriptor)


def behaviour_columns(described: Any, name: str) -> dict[str, Any]:
    """A descriptor's return as trials-table columns, checked (ValueError naming it)."""
    field = f"task.descriptor ({name})"
    if not isinstance(described, Mapping):
        raise ValueError(f"{field} must return a mapping of names to numbers, got {described!r}")
    columns: dict[str, Any] = {}
    for key, value in described.items():
        if key == "label":
            if not isinstance(value, str) or not value.strip() or len(value.splitlines()) != 1:
                raise ValueError(
                    f"{field}: label must be non-empty text on one line, got {value!r}"
                )
            columns["label"] = value
            continue
        if not isinstance(key, str) or not NAME.fullmatch(key):
            raise ValueError(f"{field}: {key!r} is not a name (letters, digits, _)")
        number = value.item() if isinstance(value, np.generic) else value
        if not isinstance(number, (int, float)) or not math.isfinite(float(number)):
            raise ValueError(f"{field}: {key} must be a finite number, got {value!r}")
        columns[PREFIX + key] = float(number)
    return columns


__all__ = [
    "EpisodeTrace",
    "behaviour_columns",
    "behaviour_names",
    "check_descriptor",
    "describe_optimum",
    "trace_episode",
]
