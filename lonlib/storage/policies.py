"""A stored optimum as a policy a Gymnasium user can step: the exact path outside lonlib.

``load_policy(folder, p, run, index)`` reads one stored local search's Actor and the
experiment's physics from its manifest, and returns a callable from one observation to one
action. Stepped through ``gymnasium.make(ENV_ID, observation_dtype="float64", **policy.env)``
from ``reset(seed=policy.eval_seed)``, its episode is the stored one, bit for bit: the sum of
``info["upright"]`` over the episode, divided by ``policy.env["steps"]``, is the stored
fitness. Two things break that (docs/rollout.md, "Replaying an optimum outside lonlib"): the
default float32 observations round the sensors, and a torch or float32 forward pass rounds
otherwise than the defined float64 one; the fitness is chaotic in those bits.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lonlib.storage.layout import optimum_path, stored_config
from lonlib.storage.trials import read_optimum
from lonlib.task.policy import actor_spec, forward_numpy

__all__ = ["StoredPolicy", "gymnasium_fitness", "gymnasium_mismatches", "load_policy"]


@dataclass(frozen=True, eq=False)
class StoredPolicy:
    """A stored Actor as a greedy policy: ``policy(observation [10 n]) -> action [n]``
    (float64, the defined forward pass of :func:`lonlib.task.policy.forward_numpy`)."""

    theta: np.ndarray
    """The Actor's flat parameters as stored (float32, the paper's Eq. 1 order)."""
    fitness: float
    """The fitness stored with it (Algorithm 1 from the nominal start)."""
    env: dict[str, Any]
    """The experiment's physics: keyword arguments of ``gymnasium.make`` (and of
    :class:`~lonlib.config.PendulumConfig`)."""
    eval_seed: int
    """The seed of the nominal start: ``env.reset(seed=eval_seed)``."""

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        spec = actor_spec(int(self.env["n_carts"]))
        rows = np.asarray(observation, dtype=np.float64).reshape(-1, spec.sizes[0])
        actions = forward_numpy(spec, self.theta, rows)
        return actions[0] if np.ndim(observation) == 1 else actions


def load_policy(
    folder: str | Path, p: float, run: int, index: int, check_seal: bool = True
) -> StoredPolicy:
    """Local search ``index`` of run ``run`` at perturbation strength ``p`` of the stored
    experiment ``folder``, as a :class:`StoredPolicy` whose fitness is the trials table's
    (ValueError naming the file when it is not stored). With ``check_seal``, data that no
    longer match the folder's seal are refused first (:mod:`lonlib.storage.digests`)."""
    from lonlib.storage.digests import check_readable
    from lonlib.storage.layout import read_manifest, trials_path
    from lonlib.storage.trials import read_trials

    root = Path(folder)
    if check_seal:
        check_readable(root, read_manifest(root), "load_policy")
    config = stored_config(root)
    path = optimum_path(root, p, run, index)
    if not path.is_file():
        raise ValueError(f"{path}: no stored Actor (is p={p!r}, run={run}, index={index} right?)")
    optimum = read_optimum(path)
    table = read_trials(trials_path(root, p, run))
    return StoredPolicy(
        theta=np.asarray(optimum.theta),
        fitness=float(table["fitness"].iloc[index]),
        env=dataclasses.asdict(config.env),
        eval_seed=int(config.ddpg.eval_seed),
    )


def gymnasium_fitness(policy: StoredPolicy, observation_dtype: str = "float64") -> float:
    """The fitness of ``policy``'s episode stepped through ``gymnasium.make`` as a user outside
    lonlib would: ``reset(seed=eval_seed)``, the policy on each observation, the sum of
    ``info["upright"]`` divided by the episode's nominal steps."""
    import gymnasium

    from lonlib.task.env import ENV_ID, register_envs

    register_envs()
    env = gymnasium.make(ENV_ID, observation_dtype=observation_dtype, **policy.env)
    observation, _ = env.reset(seed=policy.eval_seed)
    upright = 0.0
    while True:
        observation, _, terminated, truncated, info = env.step(policy(observation))
        upright += info["upright"]
        if terminated or truncated:
            env.close()
            return upright / policy.env["steps"]


def gymnasium_mismatches(folder: str | Path) -> tuple[int, list[str]]:
    """Replay every accepted optimum of ``folder`` through ``gymnasium.make`` with float64
    observations (:func:`gymnasium_fitness`): how many, and one line per optimum whose
    episode's fitness is not its stored fitness, bit for bit."""
    from lonlib.storage.digests import check_readable
    from lonlib.storage.layout import read_manifest
    from lonlib.storage.trials import read_experiment_trials

    check_readable(Path(folder), read_manifest(Path(folder)), "lonlib verify --gymnasium")
    trials = read_experiment_trials(Path(folder))
    accepted = trials[trials["accepted"].astype(bool)]
    mismatches = []
    for row in accepted.itertuples():
        policy = load_policy(folder, row.p, int(row.run), int(row.index), check_seal=False)
        replayed = gymnasium_fitness(policy)
        if replayed != policy.fitness:
            mismatches.append(
                f"p={row.p:g} run {row.run} search {row.index}: stored {policy.fitness!r}, "
                f"through gymnasium.make {replayed!r}"
            )
    return len(accepted), mismatches
