"""The memory a sampling session needs, checked against the machine before anything is
written (not part of a configuration's validity: a manifest written on a large machine must
still load on a laptop)."""

from __future__ import annotations

from lonlib.config import DDPGConfig, ExperimentConfig, PendulumConfig
from lonlib.experiment.runs import experiment_task

FLOAT_BYTES = 4  # DDPG trains in float32
INDEX_BYTES = 8  # a minibatch's sampled row indices (int64)
HIDDEN_UNITS = 4 * 20  # the Actor's and Critic's hidden units (four layers of 20)
NETWORK_PASSES = 2 * 2 * 2  # Actor and Critic, online and target, forward and backward
HEADROOM = 2.0
"""Allocator slack, torch's and numpy's own buffers, and a second copy of a minibatch while
it is gathered: the estimate times this must fit in the memory available."""


def search_memory_bytes(env: PendulumConfig | tuple[int, int], hp: DDPGConfig) -> int:
    """An estimate of one local search's working memory: its replay buffer (allocated whole,
    ``buffer_size`` transitions of ``2 * observation + action + 2`` floats,
    :mod:`lonlib.ddpg.replay`) and one minibatch (its transitions, their indices and the
    networks' activations and gradients). ``env``: the pendulums' physics, or a task's
    ``(observation size, action size)``."""
    obs, act = env if isinstance(env, tuple) else (env.observation_size, env.n_carts)
    transition = (2 * obs + act + 2) * FLOAT_BYTES
    minibatch = transition + INDEX_BYTES + HIDDEN_UNITS * NETWORK_PASSES * FLOAT_BYTES
    return hp.buffer_size * transition + hp.batch_size * minibatch


def task_sizes(config: ExperimentConfig) -> PendulumConfig | tuple[int, int]:
    """What :func:`search_memory_bytes` reads of the experiment's task."""
    if config.task is None:
        return config.env
    task = experiment_task(config)
    return (task.obs_size, task.action_size)


def concurrent_searches(
    config: ExperimentConfig, kind: str, workers: int, scheduler: str | None = None
) -> int:
    """Local searches this machine holds at once: a lockstep batch's ``slots`` (per worker
    process), one per worker process of a pool or of ``dask-local``'s cluster, else one (a
    remote Dask cluster's workers run on their own machines)."""
    if kind == "lockstep":
        return config.slots * max(1, workers)
    if kind == "pool" or (kind == "dask" and scheduler == "dask-local"):
        return max(1, workers)
    return 1


def available_memory_bytes() -> int:
    """The memory the machine can give a new allocation now (psutil's ``available``)."""
    import psutil

    return int(psutil.virtual_memory().available)


def check_memory(config: ExperimentConfig, searches: int, available: int | None = None) -> None:
    """MemoryError naming ``ddpg.buffer_size`` and ``ddpg.batch_size`` when ``searches``
    local searches at once need more than the memory available (``available``: bytes, by
    default the machine's now), before any folder is made."""
    need = searches * search_memory_bytes(task_sizes(config), config.ddpg)
    have = available_memory_bytes() if available is None else available
    if need * HEADROOM > have:
        gib = 2**30
        raise MemoryError(
            f"ddpg.buffer_size={config.ddpg.buffer_size} and ddpg.batch_size="
            f"{config.ddpg.batch_size} need about {need / gib:.3g} GiB for {searches} local "
            f"search(es) at once (x{HEADROOM:g} headroom), and this machine has "
            f"{have / gib:.3g} GiB available: lower them (the paper: 40000 and 2000), or run "
            "fewer searches at once (--slots, --workers)"
        )


__all__ = ["check_memory", "concurrent_searches", "search_memory_bytes"]
