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

import pandas as pd

from lonlib.analysis.claims_report import cell, markdown_table
from lonlib.util.readme_tables import splice_generated

KEYS = ["p", "run", "index"]
README_BEGIN = "<!-- claims-robust:begin (lonlib analyse data/reference --docs docs/results.md) -->"
README_END = "<!-- claims-robust:end -->"
NOT_COMPUTED = (
    "Not computed: the claims under the robust fitness need every accepted optimum's Actor "
    "stored and replayed (`lonlib analyse` warns which one is missing).\n"
)


def rescore_trials(
    trials: pd.DataFrame, replayed: pd.DataFrame, column: str = "robust_mean"
) -> pd.DataFrame:
    """``trials`` with each accepted trial's ``fitness`` replaced by ``replayed[column]`` of
    the same (p, run, index); rejected trials keep theirs (they are not LON nodes).

    ValueError, naming the first one, when an accepted trial has no replayed row (its
    Actor is not stored), since a LON re-scored in part would mix two fitnesses.
    """
    if column not in replayed:
        raise ValueError(f"replayed: no column {column!r}")
    values = replayed.set_index(KEYS)[column]
    keys = pd.MultiIndex.from_frame(trials[KEYS])
    found = values.reindex(keys).to_numpy(float)
    accepted = trials["accepted"].to_numpy(bool)
    missing = accepted & ~keys.isin(values.index)
    if missing.any():
        row = trials[missing].iloc[0]
        raise ValueError(
            f"trials: accepted trial p={row['p']}, run {int(row['run'])}, index "
            f"{int(row['index'])} has no replayed {column} (no stored Actor)"
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
        {
            "claim": nominal["claim"],
            "measure": nominal["measure"],
            "n (nominal)": nominal["n"],
            "effect (nominal)": [_effect(r) for r in nominal.itertuples(False)],
            "verdict (nominal)": nominal["verdict"],
            "n (robust)": robust["n"],
            "effect (robust)": [_effect(r) for r in robust.itertuples(False)],
            "verdict (robust)": robust["verdict"],
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


def splice_side_by_side(readme: str, markdown: str, source: str) -> str:
    """``readme`` with the text between :data:`README_BEGIN` and :data:`README_END` replaced
    by ``markdown`` (or :data:`NOT_COMPUTED` when it is empty) under a line naming the
    experiment folder ``source``; a page without the markers is returned unchanged."""
    if README_BEGIN not in readme:
        return readme
    return splice_generated(readme, README_BEGIN, README_END, markdown or NOT_COMPUTED, source)
