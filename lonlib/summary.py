"""How far an experiment is and what it found so far, per perturbation strength: the table
``analyse`` writes as ``figures/summary.csv`` and ``lonlib analyse --readme`` pastes into
the README, so that the reference experiment's state is generated, never typed."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from lonlib.claims_report import markdown_table
from lonlib.experiment import status
from lonlib.readme_tables import splice_generated
from lonlib.store import p_label, read_finished_trials

README_BEGIN = "<!-- summary:begin (lonlib analyse data/reference --readme README.md) -->"
README_END = "<!-- summary:end -->"


def behaviour_counts(labels: pd.Series) -> str:
    """``"crash 7, spinning (independent) 4"``: optima per label, most frequent first
    (ties by name); empty when nothing is labelled."""
    counts = labels.dropna().value_counts()
    ordered = sorted(counts.items(), key=lambda item: (-item[1], item[0]))
    return ", ".join(f"{label} {count}" for label, count in ordered)


def experiment_summary(folder: str | Path) -> pd.DataFrame:
    """One row per planned p of the experiment in ``folder``: runs planned, finished and
    started (:func:`lonlib.experiment.status`); local searches stored, accepted, and those
    whose optimum is fitter than its perturbed start (``improved``) or above fitness 0
    (``above_zero``); runs whose best optimum is above 0; the best fitness and the median
    of each run's best; the env steps trained; searches in flight saved in checkpoints; and
    the behaviour labels of the stored optima, most frequent first."""
    folder = Path(folder)
    trials = read_finished_trials(folder)
    rows = []
    for _, state in status(folder).iterrows():
        p = float(state["p"])
        group = trials[trials["p"] == p]
        run_best = group.groupby("run")["fitness"].max()
        rows.append(
            {
                "p": p,
                "runs": int(state["runs"]),
                "finished": int(state["finished"]),
                "started": int(state["started"]),
                "local_searches": len(group),
                "accepted": int(group["accepted"].sum()),
                "improved": int(group["improved"].sum()) if "improved" in group else 0,
                "above_zero": int((group["fitness"] > 0).sum()),
                "runs_above_zero": int((run_best > 0).sum()),
                "best_fitness": float(run_best.max()) if len(run_best) else float("nan"),
                "median_run_best": float(run_best.median()) if len(run_best) else float("nan"),
                "env_steps": int(group["env_steps"].sum()),
                "in_flight": int(state["saved_in_flight"]),
                "behaviours": behaviour_counts(group["label"]) if "label" in group else "",
            }
        )
    return pd.DataFrame(rows)


def summary_markdown(summary: pd.DataFrame) -> str:
    """The summary as a Markdown table, one row per p, env steps in millions."""
    table = pd.DataFrame(
        {
            "p": [p_label(p) for p in summary["p"]],
            "runs finished / planned": [
                f"{f} / {r}" for f, r in zip(summary["finished"], summary["runs"], strict=True)
            ],
            "local searches (accepted, improved on start, above 0)": [
                f"{n} ({a}, {i}, {z})"
                for n, a, i, z in zip(
                    summary["local_searches"],
                    summary["accepted"],
                    summary["improved"],
                    summary["above_zero"],
                    strict=True,
                )
            ],
            "runs above 0": summary["runs_above_zero"],
            "best fitness": summary["best_fitness"],
            "median of runs' best": summary["median_run_best"],
            "env steps (M)": [f"{s / 1e6:.1f}" for s in summary["env_steps"]],
            "behaviours of the optima": summary["behaviours"],
        }
    )
    return markdown_table(table) + "\n"


def splice_summary(readme: str, markdown: str, source: str) -> str:
    """``readme`` with the text between :data:`README_BEGIN` and :data:`README_END`
    replaced by ``markdown`` and a line naming the folder ``source`` it came from."""
    return splice_generated(readme, README_BEGIN, README_END, markdown, source)
