"""Stable-Baselines3's TD3, SAC or DDPG as the local search ``F(theta, omega, e, h)`` on a
Gymnasium task (:func:`sb3_local_search`), and bound to a task as Algorithm 2's
:data:`lonlib.search.algorithm.LocalSearch` (:func:`sb3_gymnasium_local_search`).

A search builds a fresh SB3 model (:func:`lonlib.sb3.model.make_model`) seeded from the
search's seed, sets its actor to ``theta`` and its critics to ``omega``
(:mod:`lonlib.sb3.params`), copies them into the target networks, and trains on the task's
environment (:class:`lonlib.sb3.env.TrainingEnv`, empty replay buffer) under lonlib's judging
rules (:class:`lonlib.sb3.callback.JudgingCallback`). What Algorithm 2 does not carry is
re-initialised at every start from the search's seed: SAC's ``log_std`` head (SB3's random
initialisation) and its entropy coefficient (1.0, learnt), the optimizers' moments, TD3's
and DDPG's action noise.

Nothing of a search in flight is stored (no SB3 ``save`` or pickles): an interrupted search
re-runs from its start and, on one torch thread (``hp.threads``) and the same machine, takes
the same steps to the same ``theta``. SB3 seeds Python's, numpy's and torch's global random
generators; a search restores them when it ends, so it leaves the process's random state as
it found it.
"""

from __future__ import annotations

import random
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import torch

from lonlib.config import DDPGConfig
from lonlib.ddpg.search_interface import task_optimum
from lonlib.ddpg.slots import LocalSearchResult
from lonlib.sb3.callback import JudgingCallback
from lonlib.sb3.env import TrainingEnv
from lonlib.sb3.model import make_model
from lonlib.sb3.params import load_parameters
from lonlib.search.algorithm import LocalOptimum, LocalSearch
from lonlib.task.gymnasium_task import GymnasiumTask


def sb3_local_search(
    task: GymnasiumTask,
    theta: np.ndarray,
    omega: np.ndarray,
    hp: DDPGConfig,
    seed: int,
    search: str,
    where: str = "local search",
) -> LocalSearchResult:
    """``F(theta, omega, e, h)`` with SB3's ``search`` (``sb3-td3``, ``sb3-sac``,
    ``sb3-ddpg``): the best judged policy as lonlib's flat Actor and Critic (every critic of
    the model, :attr:`GymnasiumTask.critic_count` of them), and its fitness. ``where`` names
    the search in an environment's error."""
    started = time.perf_counter()
    torch.set_num_threads(hp.threads)  # the thread count can change float reductions
    theta = np.asarray(theta, dtype=np.float32)
    omega = np.asarray(omega, dtype=np.float32)
    with global_random_state_kept():
        env = TrainingEnv(task, where)
        try:
            model = make_model(search, env, hp, seed)
            load_parameters(model.policy, theta, omega, task.actor_spec, task.critic_spec)
            judge = JudgingCallback(task, env, hp, theta, omega, where, started)
            model.learn(hp.max_steps, callback=judge, log_interval=None, progress_bar=False)
            return judge.result()
        finally:
            env.close()


def sb3_gymnasium_local_search(task: GymnasiumTask, hp: DDPGConfig, search: str) -> LocalSearch:
    """``F`` on a Gymnasium task: SB3's ``search`` bound to the task and ``h``; optima carry
    the task's behaviour descriptor if it has one."""

    def run(theta: np.ndarray, omega: np.ndarray, seed: int) -> LocalOptimum:
        return task_optimum(sb3_local_search(task, theta, omega, hp, seed, search), task, hp)

    return run


@contextmanager
def global_random_state_kept() -> Iterator[None]:
    """Python's, numpy's and torch's global random states as they were before the block."""
    legacy = np.random.get_state()  # noqa: NPY002 (SB3 seeds numpy's legacy generator)
    python, generator = random.getstate(), torch.get_rng_state()
    try:
        yield
    finally:
        random.setstate(python)
        np.random.set_state(legacy)  # noqa: NPY002
        torch.set_rng_state(generator)


__all__ = ["sb3_gymnasium_local_search", "sb3_local_search"]
