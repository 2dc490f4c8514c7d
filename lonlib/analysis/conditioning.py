"""Conditioning of a LON's optima: how much of its fitness an optimum keeps when its start
moves a little, measured by replaying the stored Actors through the one rollout.

Algorithm 1 scores a policy from one fixed start. Most DDPG optima are bang-bang policies
whose episode (crash step, turns) flips on a tiny change of that start, so their nominal
fitness says little about the policy. This module measures it for any experiment whose
Actors are stored:

* :func:`replay_optima`: every stored Actor of a trials table scored again (nominal fitness
  under both aggregations, the conditioning over ``M`` perturbed starts, its label from the
  replayed episode), beside what the table stores;
* :func:`retention_curve`: the share of optima keeping at least half their nominal fitness,
  and the median ratio, over start-noise levels (1e-6 to 1e-2 by default);
* :func:`conditioning_by_label`: nominal against robust fitness per behaviour label;
* :func:`edges_no_longer_improving`: LON edges (accepted transitions) whose replayed
  fitnesses would make them deteriorating: what changes when an experiment sampled under
  another arithmetic is re-scored.

Everything here re-scores a LON sampled with one estimate; it is not a LON sampled with the
other (Algorithm 2's acceptances would differ).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd

from lonlib.analysis.peaks import compare_with_paper, detect_peaks
from lonlib.config import PendulumConfig, Scoring
from lonlib.storage.layout import optimum_path
from lonlib.storage.trials import read_optimum
from lonlib.task.behaviour import describe_actors, label
from lonlib.task.rollout import score_actors

__all__ = [
    "NOISE_LEVELS",
    "conditioning_by_label",
    "edges_no_longer_improving",
    "peaks_under_both_aggregations",
    "replay_optima",
    "retention_curve",
]

NOISE_LEVELS = tuple(float(x) for x in np.logspace(-6, -2, 9))
"""Start-noise half-widths of the retention curve: 1e-6 to 1e-2, two per decade."""
KEEP_SHARE = 0.5
"""An optimum *keeps* its fitness when its robust mean is at least this share of it."""


def stored_actors(folder: Path, trials: pd.DataFrame) -> tuple[pd.DataFrame, np.ndarray]:
    """The rows of ``trials`` whose Actor is stored, and those Actors ``[k, P]``."""
    keep, thetas = [], []
    for position, row in enumerate(trials.itertuples()):
        path = optimum_path(folder, row.p, int(row.run), int(row.index))
        if path.exists():
            keep.append(position)
            thetas.append(read_optimum(path).theta)
    if not thetas:
        return trials.iloc[[]], np.zeros((0, 0), dtype=np.float32)
    return trials.iloc[keep].reset_index(drop=True), np.stack(thetas)


def replay_optima(
    folder: str | Path,
    trials: pd.DataFrame,
    config: PendulumConfig,
    scoring: Scoring = Scoring(),
    batch: int = 32,
) -> pd.DataFrame:
    """Every stored Actor of ``trials`` replayed: its stored ``fitness`` and ``label`` beside
    the replayed nominal fitness (``replayed``, ``replayed_all``, ``replayed_mean``), what
    the scoring's estimate compares (``replayed_estimate``: the nominal fitness, or the robust
    mean under ``robust``), the conditioning (``robust_mean``, ``robust_min``,
    ``robust_std``) and ``replayed_label``."""
    rows, thetas = stored_actors(Path(folder), trials)
    out = []
    for start in range(0, len(rows), batch):
        for d in describe_actors(thetas[start : start + batch], config, scoring):
            out.append(
                {
                    "replayed": d.fitness,
                    "replayed_estimate": d.robust_mean
                    if scoring.estimate == "robust"
                    else d.fitness,
                    "replayed_all": d.fitness_all,
                    "replayed_mean": d.fitness_mean,
                    "robust_mean": d.robust_mean,
                    "robust_min": d.robust_min,
                    "robust_std": d.robust_std,
                    "replayed_label": label(d),
                }
            )
    columns = ["p", "run", "index", "accepted", "fitness"] + (["label"] if "label" in rows else [])
    return pd.concat([rows[columns], pd.DataFrame(out, index=rows.index)], axis=1)


def retention_curve(
    thetas: np.ndarray,
    nominal: np.ndarray,
    config: PendulumConfig,
    levels: tuple[float, ...] = NOISE_LEVELS,
    scoring: Scoring = Scoring(),
) -> pd.DataFrame:
    """Per noise level: the share of the optima (``thetas [k, P]`` with nominal fitness
    ``nominal [k]`` > 0) whose robust mean keeps at least :data:`KEEP_SHARE` of it, and the
    median robust/nominal ratio. The experiment's ``scoring`` gives the nominal start
    (``eval_seed``), the number of starts and their seed; the same draws, scaled, at every
    level (at noise 0 every optimum keeps its fitness exactly)."""
    positive = np.asarray(nominal) > 0
    thetas, nominal = np.asarray(thetas)[positive], np.asarray(nominal)[positive]
    rows = []
    for level in levels:
        at_level = dataclasses.replace(scoring, estimate="robust", noise=float(level))
        robust = score_actors(thetas, config, at_level).fitness if len(thetas) else np.zeros(0)
        ratio = robust / nominal if len(nominal) else np.zeros(0)
        rows.append(
            {
                "noise": float(level),
                "optima": int(len(nominal)),
                "keep_share": float(np.mean(ratio >= KEEP_SHARE)) if len(ratio) else np.nan,
                "median_ratio": float(np.median(ratio)) if len(ratio) else np.nan,
            }
        )
    return pd.DataFrame(rows)


def conditioning_by_label(replayed: pd.DataFrame) -> pd.DataFrame:
    """Per replayed behaviour label: optima, median nominal and robust fitness, median ratio
    and the share keeping at least half (optima of nominal fitness 0 count as kept only if
    their robust mean is 0 too)."""
    table = replayed.assign(
        ratio=np.where(
            replayed["replayed"] > 0, replayed["robust_mean"] / replayed["replayed"], 1.0
        )
    )
    grouped = table.groupby("replayed_label", sort=True)
    out = pd.DataFrame(
        {
            "optima": grouped.size(),
            "nominal_median": grouped["replayed"].median(),
            "robust_median": grouped["robust_mean"].median(),
            "ratio_median": grouped["ratio"].median(),
            "keep_share": grouped["ratio"].apply(lambda r: float(np.mean(r >= KEEP_SHARE))),
        }
    )
    return out.reset_index().rename(columns={"replayed_label": "label"})


def edges_no_longer_improving(trials: pd.DataFrame, replayed: pd.DataFrame) -> pd.DataFrame:
    """Accepted transitions (parent -> accepted child, the LON's edges) whose replayed
    fitnesses, under the estimate Algorithm 2 compared (``replayed_estimate``), are
    deteriorating (child < parent), with stored and replayed numbers; edges whose parent or
    child has no stored Actor are skipped. Empty for an experiment that verifies."""
    score = {
        (float(r.p), int(r.run), int(r.index)): r.replayed_estimate for r in replayed.itertuples()
    }
    stored = {(float(r.p), int(r.run), int(r.index)): r.fitness for r in trials.itertuples()}
    rows = []
    for r in trials[trials["accepted"] & (trials["parent"] >= 0)].itertuples():
        child, parent = (
            (float(r.p), int(r.run), int(r.index)),
            (float(r.p), int(r.run), int(r.parent)),
        )
        if child in score and parent in score and score[child] < score[parent]:
            rows.append(
                {
                    "p": r.p,
                    "run": int(r.run),
                    "parent": int(r.parent),
                    "child": int(r.index),
                    "stored_parent": stored[parent],
                    "stored_child": stored[child],
                    "replayed_parent": score[parent],
                    "replayed_child": score[child],
                }
            )
    return pd.DataFrame(
        rows,
        columns=[
            *("p", "run", "parent", "child", "stored_parent", "stored_child"),
            *("replayed_parent", "replayed_child"),
        ],
    )


def peaks_under_both_aggregations(replayed: pd.DataFrame, bins: int = 50) -> pd.DataFrame:
    """Peaks of the accepted optima's replayed nominal fitness per p under both
    aggregations (``all``: every rod upright; ``mean``: the upright share), beside the
    paper's peaks (:func:`lonlib.analysis.peaks.compare_with_paper`)."""
    tables = []
    for p, group in replayed[replayed["accepted"]].groupby("p", sort=True):
        for mode, column in (("all", "replayed_all"), ("mean", "replayed_mean")):
            found = compare_with_paper(detect_peaks(group[column].to_numpy(), bins=bins))
            tables.append(found.assign(p=p, fitness_mode=mode, optima=len(group)))
    return pd.concat(tables, ignore_index=True) if tables else pd.DataFrame()
