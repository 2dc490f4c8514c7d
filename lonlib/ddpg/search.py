"""DDPG as the local search ``F(theta, omega, e, h)`` of the paper: one agent
(:func:`local_search`) or ``k`` independent agents trained together (:func:`local_search_batch`),
in the slots of a :class:`~lonlib.ddpg.trainer.SlotTrainer`."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lonlib.config import DDPGConfig, PendulumConfig
from lonlib.ddpg.slots import LocalSearchResult
from lonlib.ddpg.trainer import SlotTrainer
from lonlib.util.progress import progress_bar


def local_search(
    theta: np.ndarray,
    omega: np.ndarray,
    env_config: PendulumConfig,
    hp: DDPGConfig,
    seed: int,
    progress: bool = False,
) -> LocalSearchResult:
    """``F(theta, omega, e, h)`` for one agent: DDPG from the given Actor and Critic."""
    return local_search_batch(theta[None], omega[None], env_config, hp, [seed], progress)[0]


def local_search_batch(
    thetas: np.ndarray,
    omegas: np.ndarray,
    env_config: PendulumConfig,
    hp: DDPGConfig,
    seeds: Sequence[int],
    progress: bool = False,
) -> list[LocalSearchResult]:
    """Train ``k = len(seeds)`` independent agents together; one result per agent.

    Agent ``i`` starts from ``thetas[i]``, ``omegas[i]`` with an empty replay buffer and
    target networks copied from them, and draws every random number of its training
    (warm-up actions, exploration noise, replay sampling, episode start noise) from its own
    counter-based stream of ``seeds[i]`` (:mod:`lonlib.ddpg.streams`): its result does not
    depend on the other agents. Agents that stop early leave the batch
    (:meth:`SlotTrainer.shrink`), so the others train without carrying them.
    """
    trainer = SlotTrainer(thetas, omegas, seeds, env_config, hp)
    results: list[LocalSearchResult | None] = [None] * len(seeds)
    bar = progress_bar(
        total=hp.max_steps, desc=f"DDPG x{len(seeds)}", disable=not progress, leave=False
    )
    while trainer.busy.any():
        for tag, result in trainer.step():
            results[tag] = result
        if not trainer.busy.all():
            trainer.shrink()
        if progress and int(trainer.steps.max()) % 500 == 0:
            bar.update(500)
            best = max((r.fitness for r in trainer.results()), default=float("nan"))
            bar.set_postfix(best=f"{best:.3f}", active=int(trainer.busy.sum()))
    bar.close()
    return [result for result in results if result is not None]  # every search ends
