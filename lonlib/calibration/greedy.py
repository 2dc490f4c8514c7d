"""What trained Actors do in their greedy episodes, one table row per Actor: the behaviour
descriptor of :mod:`lonlib.task.behaviour` (one batched rollout) as the study stores it for
each search's returned Actor."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from lonlib.config import PendulumConfig, Scoring
from lonlib.task.behaviour import describe_actors, label


def greedy_rollout(
    thetas: np.ndarray, env: PendulumConfig, scoring: Scoring | int | None = None
) -> pd.DataFrame:
    """What each Actor (row of ``thetas [k, P]``) does in its greedy episode: one row per
    Actor, from :func:`lonlib.task.behaviour.describe_actors` (one batched rollout).

    Columns: ``rollout_fitness`` (Algorithm 1 under the config's ``fitness_mode``, from the
    nominal start: the fitness the search compared), ``fitness_all`` and ``fitness_mean``
    (the same episode under both aggregations), ``end_reason`` (lower-case
    :class:`~lonlib.task.pendulum.EndReason` name) and ``end_step`` (steps executed); per rod
    ``i`` ``upright_share_<i>`` (steps with the rod upright / steps **executed**, not the
    nominal steps the fitness divides by: a rod upright throughout an episode that ended
    early reads 1) and ``turns_<i>`` (signed full turns); ``cart_range`` (max x - min x
    [m], mean over carts); ``robust_mean`` and ``robust_min`` (the fitness from the
    scoring's perturbed starts); ``behaviour`` (:func:`lonlib.task.behaviour.label`).

    ``scoring`` gives the starts (:class:`lonlib.config.scoring.Scoring`, default ``Scoring()``);
    an int is read as the nominal start's ``eval_seed`` (the former ``seed`` argument).
    """
    if scoring is None:
        scoring = Scoring()
    elif not isinstance(scoring, Scoring):
        scoring = Scoring(eval_seed=int(scoring))
    descriptors = describe_actors(np.atleast_2d(np.asarray(thetas)), env, scoring)
    rows = []
    for d in descriptors:
        row: dict[str, Any] = {
            "rollout_fitness": d.fitness,
            "fitness_all": d.fitness_all,
            "fitness_mean": d.fitness_mean,
            "end_reason": d.end_reason.lower(),
            "end_step": d.end_step,
        }
        for i, (share, turns) in enumerate(zip(d.upright_share, d.turns, strict=True)):
            row[f"upright_share_{i}"] = share
            row[f"turns_{i}"] = turns
        row.update(
            {
                "cart_range": d.cart_range,
                "robust_mean": d.robust_mean,
                "robust_min": d.robust_min,
                "behaviour": label(d),
            }
        )
        rows.append(row)
    return pd.DataFrame(rows)


__all__ = ["greedy_rollout"]
