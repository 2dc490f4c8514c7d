"""The paper's claims on a LON re-scored with another fitness (issue 27, item 4).

A LON is sampled with one fitness: basin hopping accepted or rejected each local search by
it, so the LON's nodes, edges, sinks and runs' ends belong to that fitness. Re-scoring keeps
that structure and replaces each node's fitness by another estimate of the same Actor (the
robust mean over noisy starts, from :func:`lonlib.analysis.conditioning.replay_optima`).
The claims computed on it say how the *nominal* sample reads under the *robust* fitness;
they are not the claims of a LON sampled with the robust fitness, whose chains would have
accepted other searches.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from lonlib.analysis.claims import claims_from_trials
from lonlib.analysis.claims_report import cell, markdown_table
from lonlib.util.readme_tables import has_markers, splice_generated

KEYS = ["p", "run", "index"]
README_BEGIN = "<!-- claims-robust:begin (lonlib analyse data/reference --docs docs/results.md) -->"
README_END = "<!-- claims-robust:end -->"
NOT_COMPUTED = (
    "Not computed: the claims under the robust fitness need every accepted optimum's Actor "
    "stored and replayed (`lonlib analyse` warns why it skipped them).\n"
)
FILES = ("claims_robust.csv", "claims_nominal_robust.csv", "claims_nominal_robust.md")
"""What :func:`write_robust_claims` writes under an experiment's ``figures/``."""


def rescore_trials(
    trials: pd.DataFrame, replayed: pd.DataFrame, column: str = "robust_mean"
) -> pd.DataFrame:
    """``trials`` with each accepted trial's ``fitness`` replaced by ``replayed[column]`` of
    the same (p, run, index); rejected trials keep theirs (they are not LON nodes).

    ValueError, naming the first one, when an accepted trial has no replayed value (its
    Actor is not stored) or a NaN one, since a LON re-scored in part would mix two
    fitnesses; and when ``replayed`` holds a (p, run, index) twice.
    """
    if column not in replayed:
        if len(replayed):
            raise ValueError(f"replayed: no column {column!r}")
        replayed = replayed.assign(**{column: np.array([], float)})  # nothing replayed
    values = replayed.set_index(KEYS)[column]
    if not values.index.is_unique:
        p, run, index = values.index[values.index.duplicated()][0]
        raise ValueError(f"replayed: p={p}, run {run}, index {index} is there twice")
    keys = pd.MultiIndex.from_frame(trials[KEYS])
    found = values.reindex(keys).to_numpy(float)
    accepted = trials["accepted"].to_numpy(bool)
    missing = accepted & np.isnan(found)
    if missing.any():
        row = trials[missing].iloc[0]
        raise ValueError(
            f"trials: accepted trial p={row['p']}, run {int(row['run'])}, index "
            f"{int(row['index'])} has no replayed {column} (no stored Actor, or NaN)"
        )
    out = trials.copy()
    out.loc[accepted, "fitness"] = found[accepted]
    return out


def _effect(row) -> str:
    if pd.isna(row.effect):
        return ""
    return f"{cell(float(row.effect))} [{cell(float(row.ci_low))}, {cell(float(row.ci_high))}]"


def claims_side_by_side(nominal: pd.DataFrame, robust: pd.DataFrame) -> pd.DataFrame:
    """One row per claim: its n, effect with the 90 % interval and verdict under the
    nominal fitness beside the same under the re-scored (robust) one."""
    if list(nominal["claim"]) != list(robust["claim"]):
        raise ValueError("nominal and robust claims tables list different claims")
    return pd.DataFrame(
        {  # by position: the two tables' indexes need not agree
            "claim": nominal["claim"].to_numpy(),
            "measure": nominal["measure"].to_numpy(),
            "n (nominal)": nominal["n"].to_numpy(),
            "effect (nominal)": [_effect(r) for r in nominal.itertuples(False)],
            "verdict (nominal)": nominal["verdict"].to_numpy(),
            "n (robust)": robust["n"].to_numpy(),
            "effect (robust)": [_effect(r) for r in robust.itertuples(False)],
            "verdict (robust)": robust["verdict"].to_numpy(),
        }
    )


def side_by_side_markdown(table: pd.DataFrame) -> str:
    """:func:`claims_side_by_side` as Markdown, under a line that says what it is."""
    return (
        "The claims under the nominal fitness (as sampled) beside the same LONs re-scored "
        "with each node's robust mean (`claims_robust.csv`): a re-scoring of a LON sampled "
        "with the nominal fitness, not a LON sampled with the robust one.\n\n"
        + markdown_table(table)
        + "\n"
    )


def write_robust_claims(
    trials: pd.DataFrame,
    replayed: pd.DataFrame,
    nominal: pd.DataFrame,
    out: str | Path,
    bins: int = 50,
    fitness_tolerance: float = 1e-9,
) -> tuple[pd.DataFrame, pd.DataFrame, list[Path]]:
    """The claims of the LONs of ``trials`` re-scored with the replayed robust means
    (:func:`rescore_trials`) and their table beside the ``nominal`` claims
    (:func:`claims_side_by_side`), written into the folder ``out`` as :data:`FILES`:
    ``(robust claims, side-by-side table, paths written)``.

    When the re-scoring is refused (an accepted optimum without a replayed Actor, as in an
    experiment stored before Actors were kept) it warns why, removes the files an earlier
    analysis left, and returns empty tables and no paths."""
    out = Path(out)
    try:
        rescored = rescore_trials(trials, replayed)
    except ValueError as error:
        for name in FILES:
            (out / name).unlink(missing_ok=True)
        warnings.warn(f"claims under the robust fitness skipped: {error}", stacklevel=2)
        return pd.DataFrame(), pd.DataFrame(), []
    robust = claims_from_trials(rescored, bins, fitness_tolerance)
    side = claims_side_by_side(nominal, robust)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / name for name in FILES]
    robust.to_csv(paths[0], index=False)
    side.to_csv(paths[1], index=False)
    paths[2].write_text(side_by_side_markdown(side), encoding="utf-8")
    return robust, side, paths


def splice_side_by_side(readme: str, markdown: str, source: str) -> str:
    """``readme`` with the text between :data:`README_BEGIN` and :data:`README_END` replaced
    by ``markdown`` (or :data:`NOT_COMPUTED` when it is empty) under a line naming the
    experiment folder ``source``; a page without the markers is returned unchanged."""
    if not has_markers(readme, README_BEGIN):
        return readme
    return splice_generated(readme, README_BEGIN, README_END, markdown or NOT_COMPUTED, source)
