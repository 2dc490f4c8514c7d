"""The top of a LON: the optima that hold their rods, and how tightly.

An optimum *holds* when, from the first step at which every rod is upright (the fitness's
test, ``PendulumConfig.upright_angle``), every rod stays upright to the end of a full-length
episode: its fitness is then one minus its swing-up time, and optima on such a plateau differ
only in how they hold. The behaviour labels (:mod:`lonlib.task.behaviour`) call a hold
``balancing`` only when it is slow; a DDPG controller that chatters (its velocity motor
reversing at a high rate, the rod vibrating in a narrow band) is labelled ``swinging high``.
This module measures the hold from each stored Actor's greedy rollout from the fixed start
(the same rollout as the stored fitness) and sets the stored labels beside those of a
chatter-tolerant balance speed (:data:`CHATTER_TOLERANT`), so a reader sees what the
threshold decides. ``lonlib analyse --docs`` pastes the table between the markers
:data:`README_BEGIN` and :data:`README_END` of a page that holds them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from lonlib.analysis.claims_report import markdown_table
from lonlib.analysis.conditioning import stored_actors
from lonlib.analysis.summary import behaviour_counts
from lonlib.config import PendulumConfig, Scoring
from lonlib.task.behaviour import PREFIX, BehaviourThresholds, descriptors_of, label
from lonlib.task.rollout import Rollout, run_actors
from lonlib.util.labels import p_label
from lonlib.util.readme_tables import has_markers, splice_generated

README_BEGIN = "<!-- holding:begin (lonlib analyse data/one-cart --docs docs/one-cart.md) -->"
README_END = "<!-- holding:end -->"
NOT_COMPUTED = (
    "*Not computed: no accepted optimum with a stored Actor (`lonlib analyse` replays the "
    "stored Actors to measure how they hold).*\n"
)
"""The block's text when there is nothing to measure."""

HOLD_FROM_STEP = 400
"""The step from which :func:`holding_table` measures how far the rods wander
(``hold_angle_p90``): past every holding one-cart optimum's swing-up (46-52 steps) and the
overshoot that follows it."""

CHATTER_TOLERANT = BehaviourThresholds(balance_speed=2.5)
"""The default label rules with a balance speed that admits most of DDPG's chatter: the
one-cart plateau's optima hold their rod at a stored mean ``|phi_dot|`` while upright of
up to ~3 rad/s (docs/one-cart.md), against 0.06 rad/s for the swing-up controller's smooth
hold the default (0.5 rad/s) was set from. It changes no label of ``data/reference``."""

COLUMNS = (
    "p",
    "run",
    "index",
    "fitness",
    "label",
    "holds",
    "swing_up_steps",
    "hold_angle_p90",
    "upright_speed",
    "label_chatter_tolerant",
)
"""The columns of :func:`holding_table`."""


def hold_measures(
    rollout: Rollout, config: PendulumConfig, hold_from: int = HOLD_FROM_STEP
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per row of a traced ``rollout`` (``[B]`` arrays): whether it holds (every rod upright
    from the first all-upright step to the end of an episode of ``config.steps``), the
    steps before that first all-upright step (-1 when there is none), and the 90th
    percentile over the steps from ``hold_from`` to the episode's end of the largest rod
    angle from upright in radians (NaN when the episode ends before ``hold_from``)."""
    if rollout.trace is None:
        raise ValueError("hold_measures needs a rollout run with trace=True")
    trace = rollout.trace
    all_up = trace.upright.all(axis=2)  # [T, B]
    steps = np.arange(all_up.shape[0])[:, None]
    ended = steps >= rollout.end_step[None, :]
    first = np.where(all_up.any(axis=0), all_up.argmax(axis=0), -1)
    full_length = rollout.end_step == config.steps
    stays = ((steps < first[None, :]) | all_up).all(axis=0)  # a full episode has no end before T
    holds = full_length & (first >= 0) & stays
    angle = np.abs(np.angle(np.exp(1j * trace.phi))).max(axis=2)  # [T, B], wrapped
    late = np.where(ended | (steps < hold_from), np.nan, angle)
    p90 = np.full(late.shape[1], np.nan)
    some = ~np.isnan(late).all(axis=0)
    if some.any():
        p90[some] = np.nanquantile(late[:, some], 0.9, axis=0)
    return holds, first, p90


NEEDED = ("p", "run", "index", "accepted", "fitness", "label", f"{PREFIX}end_reason")
"""The trials columns :func:`holding_table` reads, besides each rod's descriptor."""


def needed_columns(n_carts: int) -> list[str]:
    """The trials columns :func:`holding_table` reads for ``n_carts`` rods: :data:`NEEDED`
    and each rod's stored mean ``|phi_dot|`` while upright."""
    return [*NEEDED, *(f"{PREFIX}upright_speed_{rod}" for rod in range(n_carts))]


def holding_table(
    folder: str | Path,
    trials: pd.DataFrame,
    config: PendulumConfig,
    scoring: Scoring = Scoring(),
    hold_from: int = HOLD_FROM_STEP,
    tolerant: BehaviourThresholds = CHATTER_TOLERANT,
    batch: int = 32,
) -> pd.DataFrame:
    """One row per accepted optimum of ``trials`` whose Actor is stored in ``folder``
    (columns :data:`COLUMNS`), rolled out ``batch`` Actors at a time from the nominal start
    of ``scoring`` (the start the stored fitness was scored from): ``holds`` (every rod
    upright from the first all-upright step to the end of a full-length episode),
    ``swing_up_steps`` (the steps before that first all-upright step, so that a holding
    optimum's fitness is ``1 - swing_up_steps / steps`` under the "all rods upright"
    aggregation, and with one rod under either; -1 when no step has every rod upright),
    ``hold_angle_p90`` (the 90th
    percentile over the steps from ``hold_from`` of the largest rod angle from upright, in
    radians; NaN for an episode that ends before ``hold_from``), ``upright_speed`` (the
    stored descriptor's mean ``|phi_dot|`` while upright, the fastest rod), and the label
    under ``tolerant`` beside the stored one (:func:`hold_measures` says how the hold is
    measured)."""
    speed_columns = [f"{PREFIX}upright_speed_{rod}" for rod in range(config.n_carts)]
    missing = [c for c in needed_columns(config.n_carts) if c not in trials.columns]
    if missing:
        raise ValueError(f"trials: the holding table needs the columns {missing}")
    accepted = trials[trials["accepted"].astype(bool)]
    rows, thetas = stored_actors(Path(folder), accepted)
    if rows.empty:
        return pd.DataFrame(columns=list(COLUMNS))
    descriptors = descriptors_of(rows)
    if any(d is None for d in descriptors):
        raise ValueError("trials: an accepted optimum has no stored behaviour descriptor")
    measures = [
        hold_measures(
            run_actors(
                thetas[start : start + batch], config, eval_seed=scoring.eval_seed, trace=True
            ),
            config,
            hold_from,
        )
        for start in range(0, len(rows), batch)
    ]
    holds, first, p90 = (np.concatenate(part) for part in zip(*measures, strict=True))
    return pd.DataFrame(
        {
            "p": rows["p"].to_numpy(),
            "run": rows["run"].to_numpy(),
            "index": rows["index"].to_numpy(),
            "fitness": rows["fitness"].to_numpy(),
            "label": rows["label"].to_numpy(),
            "holds": holds,
            "swing_up_steps": first,
            "hold_angle_p90": p90,
            "upright_speed": rows[speed_columns].max(axis=1).to_numpy(),
            "label_chatter_tolerant": [label(d, tolerant) for d in descriptors],
        },
        columns=list(COLUMNS),
    )


def _span(values: pd.Series, fmt: str) -> str:
    """``"lo-hi (median m)"`` of ``values``, or ``"lo"`` when they are one value."""
    values = values.dropna()
    if values.empty:
        return ""
    low, high, median = values.min(), values.max(), values.median()
    if low == high:  # one value: no range, no median
        return format(low, fmt)
    return f"{low:{fmt}}–{high:{fmt}} (median {median:{fmt}})"


def holding_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per p of :func:`holding_table`'s ``table``: the accepted optima and those that hold;
    over the holding ones, their fitness, the most frequent fitness and how many share it
    (the plateau), the swing-up steps, ``hold_angle_p90`` and ``upright_speed`` as
    ranges with medians, and their labels stored and under the chatter-tolerant rules."""
    rows = []
    for p in sorted(table["p"].unique(), reverse=True):  # the larger p first, as the summary
        group = table[table["p"] == p]
        held = group[group["holds"]]
        top = held["fitness"].mode()
        rows.append(
            {
                "p": p,
                "accepted": len(group),
                "holding": len(held),
                "runs_holding": held["run"].nunique(),
                "fitness": _span(held["fitness"], ".4f"),
                "plateau_fitness": float(top.max()) if len(top) else float("nan"),
                "at_plateau": int((held["fitness"] == top.max()).sum()) if len(top) else 0,
                "swing_up_steps": _span(held["swing_up_steps"], ".0f"),
                "hold_angle_p90": _span(held["hold_angle_p90"], ".2g"),
                "upright_speed": _span(held["upright_speed"], ".2f"),
                "labels": behaviour_counts(held["label"]),
                "labels_chatter_tolerant": behaviour_counts(held["label_chatter_tolerant"]),
            }
        )
    return pd.DataFrame(rows)


def holding_markdown(summary: pd.DataFrame) -> str:
    """:func:`holding_summary` as a Markdown table, one row per p; :data:`NOT_COMPUTED`
    when it has no row."""
    if summary.empty:
        return NOT_COMPUTED
    table = pd.DataFrame(
        {
            "p": [p_label(p) for p in summary["p"]],
            "accepted optima that hold (runs)": [
                f"{h} of {a} ({r} runs)"
                for h, a, r in summary[["holding", "accepted", "runs_holding"]].itertuples(False)
            ],
            "their fitness": summary["fitness"],
            "at the plateau": [
                f"{n} at {f:.4f}" if n else ""
                for n, f in summary[["at_plateau", "plateau_fitness"]].itertuples(False)
            ],
            "steps to swing up": summary["swing_up_steps"],
            f"90th percentile of |φ| from step {HOLD_FROM_STEP} (rad)": summary["hold_angle_p90"],
            "mean |φ̇| while upright (rad/s)": summary["upright_speed"],
            "labels (stored)": summary["labels"],
            f"labels, balance speed {CHATTER_TOLERANT.balance_speed:g} rad/s": summary[
                "labels_chatter_tolerant"
            ],
        }
    )
    return markdown_table(table) + "\n"


def splice_holding(readme: str, markdown: str, source: str) -> str:
    """``readme`` with its holding block replaced by ``markdown`` (or :data:`NOT_COMPUTED`
    when it is empty) under a line naming the folder ``source``; a page without the markers
    is returned unchanged."""
    if not has_markers(readme, README_BEGIN):
        return readme
    return splice_generated(readme, README_BEGIN, README_END, markdown or NOT_COMPUTED, source)
