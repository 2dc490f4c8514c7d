"""How far an experiment is and what it found so far, per perturbation strength: the table
``analyse`` writes as ``figures/summary.csv`` and ``lonlib analyse --docs`` pastes into
docs/results.md, so that the reference experiment's state is generated, never typed."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from lonlib.analysis.claims_report import markdown_table
from lonlib.storage.status import run_status
from lonlib.storage.trials import read_finished_trials
from lonlib.util.labels import p_label
from lonlib.util.readme_tables import splice_generated

README_BEGIN = "<!-- summary:begin (lonlib analyse data/reference --docs docs/results.md) -->"
README_END = "<!-- summary:end -->"


def behaviour_counts(labels: pd.Series) -> str:
    """``"crash 7, spinning (independent) 4"``: optima per label, most frequent first
    (ties by name); empty when nothing is labelled."""
    counts = labels.dropna().value_counts()
    ordered = sorted(counts.items(), key=lambda item: (-item[1], item[0]))
    return ", ".join(f"{label} {count}" for label, count in ordered)


def experiment_summary(folder: str | Path, trials: pd.DataFrame | None = None) -> pd.DataFrame:
    """One row per planned p of the experiment in ``folder``, over its planned runs only
    (:func:`lonlib.experiment.running.run_status`): runs planned, finished and started; local
    searches stored, accepted, and those whose optimum is fitter than its perturbed start
    (``improved``) or above fitness 0 (``above_zero``); runs whose best (their incumbent,
    as ``status`` has it) is above 0; the best fitness and the median of the runs' best;
    the env steps trained; searches in flight saved in checkpoints (``in_flight``) and
    their env steps; the behaviour labels of the accepted optima (the LON's nodes; a
    rejected search's optimum is no node), most frequent first.
    ``trials``: the stored trials when the caller has read them already (``analyse``), so
    that the summary counts the same trials as its figures."""
    folder = Path(folder)
    trials = read_finished_trials(folder) if trials is None else trials
    runs = run_status(folder)
    rows = []
    for p, planned in runs.groupby("p", sort=False):
        group = trials[(trials["p"] == p) & trials["run"].isin(planned["run"])]
        best = planned["best_fitness"].dropna()
        rows.append(
            {
                "p": p,
                "runs": len(planned),
                "finished": int((planned["state"] == "finished").sum()),
                "started": int((planned["state"] == "started").sum()),
                "local_searches": len(group),
                "accepted": int(group["accepted"].sum()),
                "improved": int(group["improved"].sum()),
                "above_zero": int((group["fitness"] > 0).sum()),
                "runs_above_zero": int((best > 0).sum()),
                "best_fitness": float(best.max()) if len(best) else float("nan"),
                "median_run_best": float(best.median()) if len(best) else float("nan"),
                "env_steps": int(group["env_steps"].sum()),
                "in_flight": int(planned["in_flight"].sum()),
                "in_flight_steps": int(planned["in_flight_steps"].sum()),
                "behaviours": (
                    behaviour_counts(group.loc[group["accepted"].astype(bool), "label"])
                    if "label" in group
                    else ""
                ),
            }
        )
    return pd.DataFrame(rows)


def summary_markdown(summary: pd.DataFrame) -> str:
    """The summary as a Markdown table, one row per p, env steps in millions."""
    columns = summary[
        ["finished", "started", "runs", "local_searches", "accepted", "improved", "above_zero"]
    ]
    table = pd.DataFrame(
        {
            "p": [p_label(p) for p in summary["p"]],
            "runs finished / in progress / planned": [
                f"{f} / {s} / {r}" for f, s, r, *_ in columns.itertuples(False)
            ],
            "local searches (accepted, improved on start, above 0)": [
                f"{n} ({a}, {i}, {z})" for *_, n, a, i, z in columns.itertuples(False)
            ],
            "runs above 0": summary["runs_above_zero"],
            "best fitness": summary["best_fitness"],
            "median of runs' best": summary["median_run_best"],
            "env steps (M)": [f"{s / 1e6:.2f}" for s in summary["env_steps"]],
            "searches in flight (env steps, M)": [
                f"{n} ({s / 1e6:.2f})"
                for n, s in zip(summary["in_flight"], summary["in_flight_steps"], strict=True)
            ],
            "behaviours of the accepted optima": summary["behaviours"],
        }
    )
    return markdown_table(table) + "\n"


def splice_summary(readme: str, markdown: str, source: str) -> str:
    """``readme`` with the text between :data:`README_BEGIN` and :data:`README_END`
    replaced by ``markdown`` and a line naming the folder ``source`` it came from."""
    return splice_generated(readme, README_BEGIN, README_END, markdown, source)
