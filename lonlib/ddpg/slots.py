"""What lives in a slot of the slot trainer (:mod:`lonlib.ddpg.trainer`): one local search's
bookkeeping (:class:`SlotSearch`), what it records and returns (:class:`EpisodeRecord`,
:class:`LocalSearchResult`), how it judges an improvement, and the names of the per-slot
arrays a batch carries (the checkpoints, :mod:`lonlib.ddpg.checkpoint`, store them)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class EpisodeRecord:
    """One training episode of one agent."""

    episode: int
    env_steps: int  # the agent's environment steps when the episode ended
    episode_return: float
    episode_length: int
    greedy_fitness: float
    greedy_return: float  # the greedy episode's reward sum (the plateau tie-breaker)
    critic_loss: float  # mean over the episode's updates (nan before the warm-up ends)
    actor_loss: float
    seconds: float  # since the local search started


@dataclass
class LocalSearchResult:
    """What ``F(theta, omega, e, h)`` returns for one agent."""

    fitness: float
    theta: np.ndarray  # Actor parameters at the best greedy fitness, float32 [P_actor]
    omega: np.ndarray  # Critic parameters at that point, float32 [P_critic]
    start_fitness: float  # greedy fitness of the (perturbed) start parameters
    env_steps: int
    seconds: float
    stop_reason: str  # "patience" or "budget"
    updates: int = 0  # DDPG updates of this agent
    final_evaluation: bool = False  # no policy was judged: the Actor at the stop was
    history: list[EpisodeRecord] = field(default_factory=list)

    @property
    def improved(self) -> bool:
        """Did DDPG return something strictly fitter than its start?"""
        return self.fitness > self.start_fitness


def starting_result(
    theta: np.ndarray, omega: np.ndarray, start_fitness: float, count_start: bool
) -> LocalSearchResult:
    """What a one-agent local search holds before it judges a trained policy: its start's
    parameters and greedy fitness, the start a candidate only with ``count_start``."""
    return LocalSearchResult(
        fitness=start_fitness if count_start else -np.inf,
        theta=theta.copy(),
        omega=omega.copy(),
        start_fitness=start_fitness,
        env_steps=0,
        seconds=0.0,
        stop_reason="budget",
    )


def is_improvement(
    candidate: tuple[float, float], incumbent: tuple[float, float], plateau_tiebreak: bool
) -> bool:
    """Does a greedy ``(fitness, return)`` beat the best so far? Higher fitness always does;
    with ``plateau_tiebreak``, equal fitness and a higher reward return does too."""
    if candidate[0] != incumbent[0] or not plateau_tiebreak:
        return candidate[0] > incumbent[0]
    return candidate[1] > incumbent[1] + 1e-9


HISTORY_COLUMNS = tuple(f.name for f in dataclasses.fields(EpisodeRecord))
# The per-slot numpy arrays of a SlotTrainer (its other per-slot tensor is ``loss_sum``).
SLOT_ARRAYS = (
    "busy",
    "steps",
    "updates",
    "episodes",
    "episode_return",
    "last_improvement",
    "dirty",
    "loss_count",
    "obs",
)
JUDGE_BATCH = 16  # at most this many queued greedy evaluations per batched rollout


@dataclass
class SlotSearch:
    """Host-side bookkeeping of the local search in one slot (touched only at events)."""

    tag: Any
    theta: np.ndarray  # start parameters
    omega: np.ndarray
    result: LocalSearchResult
    best: tuple[float, float]  # greedy (fitness, return) of the returned parameters so far
    started: float  # time.perf_counter() at its start
    pending: int = 0  # its policies queued for a greedy evaluation
