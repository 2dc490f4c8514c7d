"""A Gymnasium environment as the task of Algorithm 2 (:class:`GymnasiumTask`).

The adapter gives the local search and the analysis what the coupled pendulums give them:
the Actor's and Critic's shapes (from the observation and action spaces), the map from the
Actor's sigmoid output in [0, 1] to the action space's Box bounds, scaled observations, and
the fitness of a deterministic policy: the return of one greedy episode from
``reset(seed=eval_seed)``, through :func:`lonlib.task.policy.forward_numpy`'s defined
arithmetic, normalised by the configuration's ``fitness_range``
(:meth:`lonlib.config.task.GymnasiumTaskConfig.normalise`).

Every call into the environment is guarded: an exception in ``reset`` or ``step``, a NaN or
infinite observation or reward, or spaces that change between calls raise
:class:`TaskEnvironmentError` naming the environment, the call and the step, so that the
run that met it stops before storing anything (what it stored before stays).

A greedy episode replays bit for bit where the environment's own arithmetic does: on the same
CPU capability and the same versions of the environment and its libraries (the manifest
records them); elsewhere within the tolerance ``lonlib verify`` states.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from lonlib.config.task import GymnasiumTaskConfig
from lonlib.task.policy import HIDDEN, NetSpec, forward_numpy
from lonlib.util.imports import import_function


class TaskEnvironmentError(RuntimeError):
    """The environment of a Gymnasium task failed or returned what it may not (one line)."""


@dataclass(frozen=True)
class Episode:
    """One greedy episode of a deterministic policy."""

    episode_return: float
    length: int
    terminated: bool  # ended by the environment, not by the step limit
    fitness: float


def make_environment(config: GymnasiumTaskConfig, render_mode: str | None = None) -> Any:
    """``gymnasium.make`` of the task's id with its kwargs and step limit; an unknown id or
    a failing constructor is one line naming ``task.gymnasium``."""
    import gymnasium

    kwargs = dict(config.kwargs)
    if config.episode_steps:
        kwargs["max_episode_steps"] = config.episode_steps
    if render_mode is not None:
        kwargs["render_mode"] = render_mode
    try:
        return gymnasium.make(config.gymnasium, **kwargs)
    except gymnasium.error.Error as error:
        raise ValueError(f"task.gymnasium {config.gymnasium!r}: {_one_line(error)}") from None
    except (ImportError, ModuleNotFoundError) as error:
        raise ValueError(
            f"task.gymnasium {config.gymnasium!r} needs a module that is not installed: "
            f"{_one_line(error)}"
        ) from None
    except Exception as error:  # the environment's own constructor
        raise ValueError(
            f"task.gymnasium {config.gymnasium!r} (kwargs {config.kwargs}) could not be made: "
            f"{type(error).__name__}: {_one_line(error)}"
        ) from None


class GymnasiumTask:
    """A Gymnasium environment with a continuous (Box) action space as Algorithm 2's task.

    Made from a :class:`GymnasiumTaskConfig`; checks the environment at once (its id, Box
    spaces of one dimension, finite action bounds), so that a run refuses a bad task before
    any compute. ``env`` is the task's own environment for greedy episodes; training makes
    its own with :meth:`make_env`.
    """

    def __init__(self, config: GymnasiumTaskConfig) -> None:
        import gymnasium

        self.config = config
        self.env = make_environment(config)
        observation_space, action_space = self.env.observation_space, self.env.action_space
        if not isinstance(action_space, gymnasium.spaces.Box):
            raise ValueError(
                f"task.gymnasium {config.gymnasium!r} has a {type(action_space).__name__} "
                "action space; the Actor needs a continuous (Box) one"
            )
        if not isinstance(observation_space, gymnasium.spaces.Box):
            raise ValueError(
                f"task.gymnasium {config.gymnasium!r} has a {type(observation_space).__name__} "
                "observation space; the Actor reads a flat Box (wrap it, e.g. FlattenObservation)"
            )
        if len(action_space.shape) != 1 or len(observation_space.shape) != 1:
            raise ValueError(
                f"task.gymnasium {config.gymnasium!r}: spaces must be one-dimensional, got "
                f"observations {observation_space.shape} and actions {action_space.shape}"
            )
        low = np.asarray(action_space.low, dtype=np.float64)
        high = np.asarray(action_space.high, dtype=np.float64)
        if not (np.isfinite(low).all() and np.isfinite(high).all()):
            raise ValueError(
                f"task.gymnasium {config.gymnasium!r}: the action bounds must be finite (the "
                f"Actor's sigmoid output is mapped onto them), got {low} .. {high}"
            )
        self.observation_space, self.action_space = observation_space, action_space
        self._checked_spaces: dict[int, tuple[Any, Any]] = {}
        self.obs_size = int(observation_space.shape[0])
        self.action_size = int(action_space.shape[0])
        self.action_low, self.action_span = low, high - low
        self._obs_centre, self._obs_scale = observation_scaling(observation_space, config)
        self.descriptor = None  # the behaviour descriptor (lonlib.task.gymnasium_behaviour)
        if config.descriptor:  # imported now: a wrong name stops before any compute
            self.descriptor = import_function(config.descriptor, "task.descriptor")
        self.descriptor_names: list[str] | None = None  # the first described optimum's
        self.episode_steps = int(config.episode_steps or self.env.spec.max_episode_steps or 0)
        if self.episode_steps <= 0:
            raise ValueError(
                f"task.episode_steps: {config.gymnasium!r} registers no step limit; set one"
            )

    # --------------------------------------------------------------- shapes and maps
    @property
    def name(self) -> str:
        """The environment id."""
        return self.config.gymnasium

    @property
    def actor_spec(self) -> NetSpec:
        """The paper's Actor shape on this task: observations in, one sigmoid per action."""
        return NetSpec((self.obs_size, *HIDDEN, self.action_size), sigmoid_output=True)

    @property
    def critic_spec(self) -> NetSpec:
        """The paper's Critic shape on this task: observations and actions in, Q out."""
        return NetSpec((self.obs_size + self.action_size, *HIDDEN, 1), sigmoid_output=False)

    @property
    def critic_count(self) -> int:
        """Critics in ``omega``, one after the other in :attr:`critic_spec`'s layout: two for
        the twin-critic searches (``sb3-td3``, ``sb3-sac``), else one."""
        return self.config.critics

    def observe(self, observation: Any) -> np.ndarray:
        """The Actor's input ``[o]`` (float64) for one raw observation."""
        return (np.asarray(observation, dtype=np.float64) - self._obs_centre) / self._obs_scale

    def env_action(self, unit_action: np.ndarray) -> np.ndarray:
        """The environment's action for the Actor's output in [0, 1] (clipped there first),
        in the action space's dtype."""
        unit = np.clip(np.asarray(unit_action, dtype=np.float64), 0.0, 1.0)
        return (self.action_low + unit * self.action_span).astype(self.action_space.dtype)

    # ------------------------------------------------------------- guarded calls
    def reset(self, env: Any, seed: int | None, where: str) -> np.ndarray:
        """``env.reset(seed=seed)``, checked; the scaled first observation."""
        try:
            observation, _ = env.reset(seed=seed)
        except Exception as error:
            raise self._failure(where, "reset", 0, error) from None
        return self._checked_observation(env, observation, where, "reset", 0)

    def step(
        self, env: Any, unit_action: np.ndarray, where: str, step: int
    ) -> tuple[np.ndarray, float, bool, bool]:
        """``env.step`` of the Actor's output, checked: (scaled observation, reward,
        terminated, truncated)."""
        try:
            observation, reward, terminated, truncated, _ = env.step(self.env_action(unit_action))
        except Exception as error:
            raise self._failure(where, "step", step, error) from None
        obs = self._checked_observation(env, observation, where, "step", step)
        try:
            value = float(reward)
        except (TypeError, ValueError):
            value = float("nan")
        if not np.isfinite(value):
            raise TaskEnvironmentError(
                f"{where}: {self.name} returned the reward {reward!r} at step {step}; "
                "rewards must be finite numbers"
            )
        return obs, value, bool(terminated), bool(truncated)

    def _checked_observation(
        self, env: Any, observation: Any, where: str, call: str, step: int
    ) -> np.ndarray:
        if not self._spaces_unchanged(env):
            raise TaskEnvironmentError(
                f"{where}: {self.name} changed its observation or action space "
                f"{_at(call, step)}; a task's spaces must stay fixed"
            )
        array = np.asarray(observation, dtype=np.float64)
        if array.shape != (self.obs_size,):
            raise TaskEnvironmentError(
                f"{where}: {self.name} returned an observation of shape {array.shape} "
                f"{_at(call, step)}, its space says ({self.obs_size},)"
            )
        if not np.isfinite(array).all():
            raise TaskEnvironmentError(
                f"{where}: {self.name} returned a non-finite observation {_at(call, step)}: "
                f"{array.tolist()}"
            )
        return self.observe(array)

    def _spaces_unchanged(self, env: Any) -> bool:
        """Are ``env``'s spaces still the task's? Compared in full once per pair of space
        objects an environment shows (the common case, the same objects, costs nothing)."""
        spaces = (env.observation_space, env.action_space)
        seen = self._checked_spaces.get(id(env))
        if seen is not None and seen[0] is spaces[0] and seen[1] is spaces[1]:
            return True
        if spaces[0] == self.observation_space and spaces[1] == self.action_space:
            self._checked_spaces[id(env)] = spaces  # holds them: their ids stay theirs
            return True
        return False

    def _failure(self, where: str, call: str, step: int, error: Exception) -> TaskEnvironmentError:
        return TaskEnvironmentError(
            f"{where}: {self.name} raised {_at(call, step)}: {type(error).__name__}: "
            f"{_one_line(error)}"
        )

    # ------------------------------------------------------------------- fitness
    def greedy_episode(
        self,
        theta: np.ndarray,
        where: str = "greedy episode",
        env: Any = None,
        on_step: Callable[[int, np.ndarray, np.ndarray, float], None] | None = None,
    ) -> Episode:
        """One greedy episode of the Actor ``theta`` from ``reset(seed=eval_seed)``: its
        return, length and fitness (the one definition of a Gymnasium task's fitness).
        ``on_step(step, observation, unit_action, reward)`` sees every step (recordings)."""
        env = self.env if env is None else env
        spec, flat = self.actor_spec, np.asarray(theta)
        obs = self.reset(env, self.config.eval_seed, where)
        total, terminated = 0.0, False
        for step in range(1, self.episode_steps + 1):
            action = forward_numpy(spec, flat, obs[None])[0]
            obs, reward, terminated, truncated = self.step(env, action, where, step)
            total += reward
            if on_step is not None:
                on_step(step, obs, action, reward)
            if terminated or truncated:
                break
        return Episode(total, step, terminated, self.config.normalise(total))

    def fitness(self, thetas: np.ndarray, where: str = "greedy episode") -> np.ndarray:
        """Fitness ``[m]`` of ``m`` flat Actors ``[m, P]`` (one greedy episode each)."""
        thetas = np.atleast_2d(thetas)
        return np.array([self.greedy_episode(t, where).fitness for t in thetas])

    def make_env(self) -> Any:
        """A fresh environment for training (same id, kwargs and step limit)."""
        return make_environment(self.config)


def environment_versions(config: GymnasiumTaskConfig) -> dict[str, Any]:
    """Where the task's environment comes from: its id, its entry point, and the
    distribution (and version) that provides the entry point's module; what a manifest
    records so that a replay knows whether it may expect the same bits."""
    from importlib import metadata

    import gymnasium

    try:
        spec = gymnasium.spec(config.gymnasium.split(":")[-1])
    except gymnasium.error.Error:
        make_environment(config).close()  # imports a ``module:Id``'s module, registering it
        spec = gymnasium.spec(config.gymnasium.split(":")[-1])
    entry = spec.entry_point
    entry_name = entry if isinstance(entry, str) else f"{entry.__module__}:{entry.__qualname__}"
    top = entry_name.split(":")[0].split(".")[0]
    distributions = metadata.packages_distributions().get(top, [])
    versions = {}
    for name in distributions:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return {
        "id": config.gymnasium,
        "entry_point": entry_name,
        "gymnasium": gymnasium.__version__,
        "distributions": versions,
    }


def observation_scaling(space: Any, config: GymnasiumTaskConfig) -> tuple[np.ndarray, np.ndarray]:
    """``(centre, half-width)`` per observation entry: the Box bounds' for ``bounds`` scaling
    (entries with an infinite or empty bound: 0 and 1, unscaled), else 0 and 1."""
    size = int(space.shape[0])
    centre, scale = np.zeros(size), np.ones(size)
    if config.observation_scaling == "bounds":
        low = np.asarray(space.low, dtype=np.float64)
        high = np.asarray(space.high, dtype=np.float64)
        usable = np.isfinite(low) & np.isfinite(high) & (high > low)
        centre[usable] = (low[usable] + high[usable]) / 2.0
        scale[usable] = (high[usable] - low[usable]) / 2.0
    return centre, scale


def _at(call: str, step: int) -> str:
    """Where in an episode a call failed: "in reset", or "at step N"."""
    return "in reset" if call == "reset" else f"at step {step}"


def _one_line(error: BaseException) -> str:
    text = " ".join(str(error).split())
    return text if len(text) <= 300 else text[:297] + "..."


__all__ = [
    "Episode",
    "GymnasiumTask",
    "TaskEnvironmentError",
    "environment_versions",
    "make_environment",
]
