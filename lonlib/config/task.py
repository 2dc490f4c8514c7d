"""The task of an experiment that is not the coupled pendulums: a Gymnasium environment, how
long its greedy episode runs, how its return becomes a fitness in [0, 1], and how its
observations reach the Actor (issue "The LON of any continuous-control task").

Only what can be checked without the environment is checked here, so that a manifest
written on a machine with, say, MuJoCo still loads for analysis on one without it: that the
id is registered and that its spaces are continuous is checked by
:class:`lonlib.task.gymnasium_task.GymnasiumTask` before any compute (``lonlib run``,
``--dry-run``, ``verify``).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from dataclasses import dataclass, field
from typing import Any

from lonlib.util.validation import check_choice, check_field_types, check_keys, check_range

OBSERVATION_SCALINGS = ("bounds", "none")
SEARCHES = ("ddpg", "sb3-td3", "sb3-sac", "sb3-ddpg")
"""Local searches ``F`` a Gymnasium task can use: lonlib's DDPG, or Stable-Baselines3's TD3,
SAC and DDPG (the optional extra ``lonlib[sb3]``)."""
CRITICS = {"ddpg": 1, "sb3-td3": 2, "sb3-sac": 2, "sb3-ddpg": 1}
"""Critics each search trains: TD3's and SAC's twin Q-networks are both in the Critic
parameters ``omega`` (concatenated, each in the task's critic layout)."""


@dataclass(frozen=True)
class GymnasiumTaskConfig:
    """A Gymnasium environment as the task ``e`` of Algorithm 2.

    The fitness of a deterministic policy is the return of one greedy episode from
    ``reset(seed=eval_seed)``, at most ``episode_steps`` long, mapped linearly from
    ``fitness_range`` onto [0, 1] and clipped there: ``(R - low) / (high - low)``.
    """

    gymnasium: str
    """The environment id given to ``gymnasium.make`` (e.g. ``Pendulum-v1``; a
    ``module:Id`` form imports ``module`` first, which is how a user's own environment
    registers itself)."""
    fitness_range: tuple[float, float]
    """Returns ``[low, high]`` mapped onto fitness 0 and 1 (required: a return's scale is the
    environment's, and the paper's fitness lies in [0, 1]). Returns outside are clipped."""
    episode_steps: int = 0
    """Steps of every episode, training and greedy (the ``TimeLimit``); 0 keeps the
    environment's registered ``max_episode_steps``."""
    kwargs: dict[str, Any] = field(default_factory=dict, hash=False)
    """Keyword arguments of ``gymnasium.make`` (JSON values only)."""
    eval_seed: int = 0
    """The seed of the greedy episode's ``reset``: the same start for every policy."""
    observation_scaling: str = "bounds"
    """``bounds``: each observation entry mapped linearly from its Box bounds onto [-1, 1]
    (entries with an infinite bound pass unscaled); ``none``: raw observations. The paper's
    Actor squashes every layer with a sigmoid, so inputs of very different scales (Mountain
    Car's position spans 1.8, its velocity 0.14) saturate or vanish."""
    search: str = "ddpg"
    """The local search ``F``: ``ddpg`` (lonlib's, the paper's), or ``sb3-td3``,
    ``sb3-sac``, ``sb3-ddpg`` (Stable-Baselines3, the extra ``lonlib[sb3]``)."""
    descriptor: str = ""
    """Optional behaviour descriptor of every optimum, ``module:function``: called with the
    optimum's scored greedy episode (:class:`lonlib.task.gymnasium_task.EpisodeTrace`), it
    returns named numbers (stored as ``b_<name>`` columns of the trials table, replayed by
    ``lonlib verify``) and optionally a ``label`` (text: the analysis groups optima by it, as
    the pendulums' behaviour labels). Empty: no descriptor."""

    def __post_init__(self) -> None:
        check_field_types(self)
        if not self.gymnasium.strip():
            raise ValueError("task.gymnasium must name a Gymnasium environment id")
        if isinstance(self.fitness_range, list):
            object.__setattr__(self, "fitness_range", tuple(self.fitness_range))
        low_high = self.fitness_range
        if (
            not isinstance(low_high, tuple)
            or len(low_high) != 2
            or not all(_finite_number(v) for v in low_high)
            or not low_high[0] < low_high[1]
        ):
            raise ValueError(
                "task.fitness_range must be two finite numbers [low, high] with low < high "
                f"(the returns mapped onto fitness 0 and 1), got {self.fitness_range!r}"
            )
        object.__setattr__(self, "fitness_range", tuple(float(v) for v in low_high))
        check_range("task.episode_steps", self.episode_steps, 0, 10_000_000)
        check_range("task.eval_seed", self.eval_seed, 0, 2**32 - 1)
        check_choice("task.observation_scaling", self.observation_scaling, OBSERVATION_SCALINGS)
        check_choice("task.search", self.search, SEARCHES)
        if self.descriptor and not DESCRIPTOR_FORM.fullmatch(self.descriptor):
            raise ValueError(
                "task.descriptor must name a function as module:function (e.g. "
                f"mypackage.descriptors:swing), got {self.descriptor!r}"
            )
        if not isinstance(self.kwargs, dict):
            raise ValueError(f"task.kwargs must be a mapping, got {self.kwargs!r}")
        try:
            json.dumps(self.kwargs, allow_nan=False)
        except (TypeError, ValueError):
            raise ValueError(
                f"task.kwargs must hold JSON values only (numbers, text, lists, mappings), "
                f"got {self.kwargs!r}"
            ) from None

    @property
    def critics(self) -> int:
        """How many critics ``omega`` holds for this task's search (:data:`CRITICS`)."""
        return CRITICS[self.search]

    def to_dict(self) -> dict[str, Any]:
        """Plain mapping (YAML/JSON friendly) that :meth:`from_mapping` reads back."""
        out = dataclasses.asdict(self)
        out["fitness_range"] = list(self.fitness_range)
        if not out["descriptor"]:  # the stored form of a task without one stays as it was
            del out["descriptor"]
        return out

    @classmethod
    def from_mapping(cls, values: Any) -> GymnasiumTaskConfig:
        """Build from the ``task:`` mapping of an experiment's YAML; unknown keys and a
        missing id or range are refused by name."""
        if not isinstance(values, dict):
            raise ValueError(f"task must be a mapping of settings, got {values!r}")
        check_keys("task", values, cls)
        for required in ("gymnasium", "fitness_range"):
            if required not in values:
                raise ValueError(
                    f"task.{required} is required for a Gymnasium task (e.g. "
                    "task: {gymnasium: Pendulum-v1, fitness_range: [-1600, 0]})"
                )
        return cls(**values)

    def normalise(self, episode_return: float) -> float:
        """The fitness of a greedy episode's return: ``fitness_range`` onto [0, 1], clipped."""
        low, high = self.fitness_range
        return min(1.0, max(0.0, (episode_return - low) / (high - low)))


DESCRIPTOR_FORM = re.compile(r"[A-Za-z_][\w.]*:[A-Za-z_]\w*")


def _finite_number(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


__all__ = ["CRITICS", "OBSERVATION_SCALINGS", "SEARCHES", "GymnasiumTaskConfig"]
