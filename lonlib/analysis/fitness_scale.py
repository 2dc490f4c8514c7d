"""Where each behaviour lands under Algorithm 1's two aggregations (issue 46, "the fitness
scale, said plainly").

The paper's text counts a step when *all* pendulums are upright (``fitness_mode: all``); its
Algorithm 1 sums over steps and carts (``mean``). Every stored trial records both from the
same episode (``b_fitness_all``, ``b_fitness_mean``), so the table below is read from the
committed experiments' accepted optima, grouped by behaviour label, with the two-cart
balancing Actor of the hold test (``data/studies/hold-test/actor.npy``) scored by the one
rollout as the top of the scale. ``python -m lonlib.analysis.fitness_scale`` pastes the table
into ``docs/results.md``; a test checks that the page holds what this module computes. What it
reads is checked against its seal first (:mod:`lonlib.storage.digests`): a changed file stops
it with one line naming the file.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

from lonlib.config import PendulumConfig
from lonlib.storage import read_finished_trials
from lonlib.storage.digests import check_files_seal
from lonlib.task import run_actors
from lonlib.util.readme_tables import splice

BEGIN = "<!-- fitness-scale:begin (python -m lonlib.analysis.fitness_scale) -->"
END = "<!-- fitness-scale:end -->"
EXPERIMENTS = ("data/reference", "data/one-cart")
BALANCING_ACTOR = "data/studies/hold-test/actor.npy"
READER = "python -m lonlib.analysis.fitness_scale"


def fitness_scale(trials: pd.DataFrame) -> pd.DataFrame:
    """Accepted optima per behaviour label: how many, and the median and highest fitness
    under ``all`` and under ``mean`` (from the trials' ``b_fitness_all`` and
    ``b_fitness_mean``), most optima first."""
    accepted = trials[trials["accepted"].astype(bool)]
    table = accepted.groupby("label").agg(
        optima=("b_fitness_all", "size"),
        all_median=("b_fitness_all", "median"),
        all_max=("b_fitness_all", "max"),
        mean_median=("b_fitness_mean", "median"),
        mean_max=("b_fitness_mean", "max"),
    )
    return table.sort_values(["optima", "all_median"], ascending=False).reset_index()


def balancing_row(actor: np.ndarray, config: PendulumConfig | None = None) -> dict:
    """The row of one Actor scored from the nominal start by the one rollout (``run_actors``)
    under both aggregations."""
    episode = run_actors(actor, config or PendulumConfig())
    return {
        "label": "balancing both rods (the hold test's imitation Actor)",
        "optima": 1,
        "all_median": float(episode.fitness_all[0]),
        "all_max": float(episode.fitness_all[0]),
        "mean_median": float(episode.fitness_mean[0]),
        "mean_max": float(episode.fitness_mean[0]),
    }


def fitness_scale_markdown(root: Path) -> str:
    """The docs table: every committed experiment's labels, then the balancing Actor (each
    read once its folder matches its seal: TamperedDataError naming the file otherwise)."""
    lines = [
        "| experiment | behaviour | optima | `all`: median (max) | `mean`: median (max) |",
        "|---|---|---|---|---|",
    ]

    def line(source: str, row: dict) -> str:
        return (
            f"| {source} | {row['label']} | {row['optima']} "
            f"| {row['all_median']:.3f} ({row['all_max']:.3f}) "
            f"| {row['mean_median']:.3f} ({row['mean_max']:.3f}) |"
        )

    for source in EXPERIMENTS:
        trials = read_finished_trials(root / source, reader=READER)
        for row in fitness_scale(trials).to_dict("records"):
            lines.append(line(f"`{source}`", row))
    check_files_seal((root / BALANCING_ACTOR).parent).raise_if_tampered(READER)
    actor = np.load(root / BALANCING_ACTOR)
    lines.append(line(f"`{BALANCING_ACTOR}`", balancing_row(actor)))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Paste the table into ``docs/results.md`` of the project at the working directory."""
    root = Path(argv[0]) if argv else Path.cwd()
    page = root / "docs" / "results.md"
    page.write_text(splice(page.read_text(), BEGIN, END, fitness_scale_markdown(root)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
