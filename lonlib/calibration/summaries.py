"""What the calibration study reports of a search and of a cell: the bars it judges by, a
search's summaries (from its per-episode history, :func:`history_summary`, and from its
described judged policies, :func:`judged_summary`) and the columns of the per-cell table
(:data:`CELL_COLUMNS`, ``calibration.csv``)."""

from __future__ import annotations

import math
from typing import Any

# Greedy fitness that only balancing reaches: every rod upright >= 90 % of the episode, swing-up
# included (a spinning rod is upright about half the time: no optimum of the default grid, all
# spinning or ending early, scores above 0.51); the study reports the env steps to the first.
BALANCING_FITNESS = 0.9
# The labels of an optimum with at least one rod balanced (lonlib.task.behaviour.label).
ROD_UP_LABELS = ("balancing", "one rod up")
AGGREGATIONS = ("all", "mean")  # fitness_mode: every rod upright per step, the upright share

CELL_COLUMNS = [
    "cell",
    "motor",
    "integrator",
    "motor_gain",
    "motor_tau",
    "reward",
    "searches",
    "left_zero",
    "share_left_zero",
    "first_nonzero_steps_min",
    "first_nonzero_steps_median",
    "first_nonzero_steps_max",
    "balanced",
    "first_balancing_steps_min",
    "first_balancing_steps_median",
    "first_balancing_steps_max",
    "best_fitness",
    "median_best_fitness",
    "behaviours",
    "best_upright_share",
    "best_turns",
    "best_end_reason",
    "best_end_step",
    "best_cart_range",
    "seconds",
]


def judged_summary(
    steps: list[int], fitness_all: list[float], fitness_mean: list[float], labels: list[str]
) -> dict[str, Any]:
    """When a search's optima got good, under both aggregations, from its judged policies
    (env steps at their episodes' ends, fitness under ``all`` and ``mean``, label).

    Under aggregation ``a`` the search's optimum changes whenever a judged policy scores
    strictly more under ``a`` than every earlier one. Per ``a``: ``best_<a>`` (0 if none was
    judged), ``first_090_<a>_steps`` (the first optimum scoring at least
    :data:`BALANCING_FITNESS`), ``first_balancing_<a>_steps`` (the first labelled
    ``balancing``) and ``first_rod_up_<a>_steps`` (the first with a rod balanced: labelled
    ``one rod up`` or ``balancing``, :data:`ROD_UP_LABELS`); None where none did.
    """
    out: dict[str, Any] = {}
    for name, fitness in zip(AGGREGATIONS, (fitness_all, fitness_mean), strict=True):
        best = -math.inf
        firsts: dict[str, int | None] = {"090": None, "balancing": None, "rod_up": None}
        for step, value, kind in zip(steps, fitness, labels, strict=True):
            if not value > best:
                continue
            best = value
            hits = {
                "090": value >= BALANCING_FITNESS,
                "balancing": kind == "balancing",
                "rod_up": kind in ROD_UP_LABELS,
            }
            for key, hit in hits.items():
                if hit and firsts[key] is None:
                    firsts[key] = int(step)
        out[f"best_{name}"] = max(best, 0.0)
        for key, first in firsts.items():
            out[f"first_{key}_{name}_steps"] = first
    return out


def history_summary(steps: list[int], fitness: list[float]) -> dict[str, Any]:
    """Best greedy fitness of a trained policy (0 if none was judged), the env steps of the
    first non-zero one and of the first at least :data:`BALANCING_FITNESS` (None if never),
    from a search's per-episode history. Episodes whose policy was not judged (before the
    first update, or between two multiples of ``judge_every``) carry no greedy fitness (NaN)
    and are skipped."""
    judged = [(s, f) for s, f in zip(steps, fitness, strict=True) if not math.isnan(f)]
    nonzero = [s for s, f in judged if f > 0]
    balancing = [s for s, f in judged if f >= BALANCING_FITNESS]
    return {
        "best_fitness": max((f for _, f in judged), default=0.0),
        "first_nonzero_steps": nonzero[0] if nonzero else None,
        "first_balancing_steps": balancing[0] if balancing else None,
    }


__all__ = [
    "AGGREGATIONS",
    "BALANCING_FITNESS",
    "CELL_COLUMNS",
    "ROD_UP_LABELS",
    "history_summary",
    "judged_summary",
]
