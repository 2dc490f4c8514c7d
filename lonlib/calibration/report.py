"""The calibration study's report: tables, Markdown and figure from its stored cells.

:func:`write_outputs` reads the cells :func:`lonlib.calibration.campaign.run_calibration`
stored and writes ``calibration.csv`` (one row per cell, :func:`cell_table`),
``searches.csv`` (one row per search, :func:`search_table`), ``drift.csv``
(:func:`lonlib.calibration.drift.integrator_drift`), ``calibration.md``
(:func:`calibration_markdown`, the table of docs/calibration.md) and ``calibration.png``
(:func:`calibration_figure`, drawn with seaborn under the figures' one theme).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import seaborn as sns

from lonlib.calibration.cell_store import read_cell
from lonlib.calibration.drift import integrator_drift
from lonlib.calibration.summaries import (
    AGGREGATIONS,
    BALANCING_FITNESS,
    CELL_COLUMNS,
    history_summary,
)
from lonlib.config import CalibrationConfig
from lonlib.storage.atomic import atomic_write
from lonlib.storage.digests import reseal_files_if_sealed
from lonlib.task.behaviour import LABELS
from lonlib.util.figures import png_bytes, themed


def search_table(records: list[dict[str, Any]]) -> pd.DataFrame:
    """One row per search: the cell's settings, fitness, steps to the first non-zero
    greedy fitness and the greedy rollout of the returned Actor."""
    rows = []
    for record in records:
        for search in record["searches"]:
            # cells stored before the start angle was a cell setting start hanging
            row = {"cell": record["name"], "initial_angle": math.pi, **record["cell"]}
            # only the velocity motor has a time constant; its gain shows only when not 1
            if row["motor"] != "velocity":
                row["motor_tau"] = np.nan
            elif row.get("motor_gain", 1.0) == 1.0:
                row["motor_gain"] = np.nan
            if "continue_from" in row:  # empty (none) reads back from a CSV as NaN
                row["continue_from"] = row["continue_from"] or np.nan
            row.update({k: v for k, v in search.items() if not k.startswith("history_")})
            # from the history, so that records stored before NaN-safe summaries read right
            row.update(
                history_summary(search["history_env_steps"], search["history_greedy_fitness"])
            )
            rows.append(row)
    table = pd.DataFrame(rows)
    for column in ("first_nonzero_steps", "first_balancing_steps", *JUDGED_STEPS):
        if column in table:
            table[column] = table[column].astype("float64")
    return table


# The per-search columns of the learner-side study (lonlib.calibration.summaries.judged_summary).
JUDGED_STEPS = tuple(
    f"first_{event}_{a}_steps" for a in AGGREGATIONS for event in ("090", "balancing", "rod_up")
)
STUDY_COLUMNS = [
    "cell",
    "reward",
    "exploring_starts",
    "continue_from",
    "initial_angle",
    "searches",
    *(
        f"{column}_{a}"
        for a in AGGREGATIONS
        for column in (
            "best",
            "median_best",
            "reached_090",
            "first_090_steps_median",
            "balancing",
            "first_balancing_steps_median",
            "rod_up",
            "first_rod_up_steps_median",
        )
    ),
]


def has_judged(searches: pd.DataFrame) -> bool:
    """Do the searches carry the learner-side study's columns (records stored since)?"""
    return "best_all" in searches and bool(searches["best_all"].notna().any())


def study_table(searches: pd.DataFrame) -> pd.DataFrame:
    """One row per cell of the learner-side study (columns :data:`STUDY_COLUMNS`): per
    aggregation (``all``: every rod upright per step, the fitness; ``mean``: the upright
    share) the best and median best fitness of the cell's searches, and how many searches
    reached an optimum of at least :data:`BALANCING_FITNESS`, one labelled ``balancing``,
    one with a rod up (``one rod up`` or ``balancing``), with the median env steps to it."""
    rows = []
    for name, group in searches.groupby("cell", sort=False):
        first = group.iloc[0]
        row: dict[str, Any] = {
            "cell": name,
            "reward": first["reward"],
            "exploring_starts": bool(first.get("exploring_starts", False)),
            "continue_from": first.get("continue_from", "")
            if pd.notna(first.get("continue_from", ""))
            else "",
            "initial_angle": float(first.get("initial_angle", math.pi)),
            "searches": len(group),
        }
        for a in AGGREGATIONS:
            row[f"best_{a}"] = float(group[f"best_{a}"].max())
            row[f"median_best_{a}"] = float(group[f"best_{a}"].median())
            for event, count in (
                ("090", "reached_090"),
                ("balancing", "balancing"),
                ("rod_up", "rod_up"),
            ):
                steps = group[f"first_{event}_{a}_steps"].dropna()
                row[f"{count}_{a}"] = len(steps)
                row[f"first_{event}_steps_median_{a}"] = steps.median() if len(steps) else np.nan
        rows.append(row)
    return pd.DataFrame(rows, columns=STUDY_COLUMNS)


def study_markdown(table: pd.DataFrame) -> str:
    """:func:`study_table` as Markdown: per cell and aggregation the best fitness (median
    best) and, for each event, ``searches reaching it, median env steps to it``."""

    def event(row: pd.Series, count: str, steps: str) -> str:
        if not row[count]:
            return f"0 of {row['searches']}"
        return f"{row[count]} of {row['searches']}, {_kilo(row[steps])}"

    head = "| cell | reward | training starts | start |"
    rule = "|---|---|---|---|"
    for a in AGGREGATIONS:
        name = "all rods upright" if a == "all" else "per-pendulum mean"
        head += (
            f" best, {name} (median) | ≥ {BALANCING_FITNESS:g} ({a}) | balancing ({a}) "
            f"| a rod up ({a}) |"
        )
        rule += "---|---|---|---|"
    lines = [head, rule]
    for _, row in table.iterrows():
        start = f"best of {row['continue_from']}" if row["continue_from"] else "initial"
        if row["initial_angle"] != math.pi:
            start += (
                ", upright"
                if row["initial_angle"] == 0.0
                else f", rods at {row['initial_angle']:.3g}"
            )
        line = (
            f"| {row['cell']} | {row['reward']} "
            f"| {'exploring' if row['exploring_starts'] else 'fixed'} | {start} |"
        )
        for a in AGGREGATIONS:
            line += (
                f" {row[f'best_{a}']:.3f} ({row[f'median_best_{a}']:.3f}) "
                f"| {event(row, f'reached_090_{a}', f'first_090_steps_median_{a}')} "
                f"| {event(row, f'balancing_{a}', f'first_balancing_steps_median_{a}')} "
                f"| {event(row, f'rod_up_{a}', f'first_rod_up_steps_median_{a}')} |"
            )
        lines.append(line)
    return "\n".join(lines) + "\n"


def best_so_far_table(records: list[dict[str, Any]]) -> pd.DataFrame:
    """The best greedy fitness so far of every search under both aggregations, at each
    judged policy that raised it and at the search's end: columns ``cell``, ``seed_index``,
    ``aggregation``, ``env_steps``, ``best`` (small: improvements only)."""
    rows = []
    for record in records:
        for search in record["searches"]:
            steps = search.get("history_judged_env_steps")
            if not steps:
                continue
            for a in AGGREGATIONS:
                best = -np.inf
                for step, value in zip(steps, search[f"history_fitness_{a}"], strict=True):
                    if value > best:
                        best = value
                        rows.append((record["name"], search["seed_index"], a, step, value))
                rows.append((record["name"], search["seed_index"], a, search["env_steps"], best))
    columns = ["cell", "seed_index", "aggregation", "env_steps", "best"]
    return pd.DataFrame(rows, columns=columns)


def study_figure(best: pd.DataFrame) -> plt.Figure:
    """Best greedy fitness so far against env steps, one panel per aggregation, one line
    per search, one colour per cell (from :func:`best_so_far_table`); drawn with seaborn
    under the figures' one theme, the balancing threshold as a dotted line."""
    cells = list(dict.fromkeys(best["cell"]))
    palette = dict(zip(cells, sns.color_palette("tab10", max(len(cells), 2)), strict=False))
    with themed():
        fig, axes = plt.subplots(1, len(AGGREGATIONS), figsize=(13, 4.5), sharey=True)
        for ax, a in zip(axes, AGGREGATIONS, strict=True):
            part = best[best["aggregation"] == a]
            if len(part):
                sns.lineplot(
                    data=part, x="env_steps", y="best", hue="cell", hue_order=cells,
                    units="seed_index", estimator=None, palette=palette,
                    drawstyle="steps-post", linewidth=1.2, alpha=0.8,
                    legend=ax is axes[-1], ax=ax,
                )  # fmt: skip
            ax.axhline(BALANCING_FITNESS, color="grey", lw=0.8, ls=":")
            ax.set_title("all rods upright (the fitness)" if a == "all" else "per-pendulum mean")
            ax.set_xlabel("environment steps")
            ax.xaxis.set_major_formatter(plt.FuncFormatter(lambda v, _: f"{v / 1000:g}k"))
            ax.set_ylim(-0.02, 1.02)
        axes[0].set_ylabel("best greedy fitness so far")
        if axes[-1].get_legend() is not None:
            sns.move_legend(
                axes[-1], "upper left", bbox_to_anchor=(1.02, 1.0), frameon=False, fontsize=7
            )
        fig.suptitle("Learner-side study: best greedy fitness so far per search")
        fig.tight_layout()
    return fig


def _per_rod(row: pd.Series, prefix: str, fmt: str) -> str:
    columns = sorted(c for c in row.index if c.startswith(prefix) and pd.notna(row[c]))
    return " / ".join(format(row[c], fmt) for c in columns)


def cell_table(searches: pd.DataFrame, records: list[dict[str, Any]]) -> pd.DataFrame:
    """One row per cell (columns :data:`CELL_COLUMNS`). ``behaviours`` counts the searches
    per label (:data:`lonlib.task.behaviour.LABELS`, most accomplished first). The ``best_*``
    columns describe the cell's best search's rollout; per-rod values are joined with ``/``
    (``best_cart_range`` is the mean over carts)."""
    seconds = {record["name"]: record["seconds"] for record in records}
    rows = []
    for name, group in searches.groupby("cell", sort=False):
        steps = group["first_nonzero_steps"].dropna()
        balancing = group["first_balancing_steps"].dropna()
        best = group.loc[group["best_fitness"].idxmax()]
        counts = group["behaviour"].value_counts()
        rows.append(
            {
                "cell": name,
                **{
                    k: best[k] for k in ("motor", "integrator", "motor_gain", "motor_tau", "reward")
                },
                "searches": len(group),
                "left_zero": int((group["best_fitness"] > 0).sum()),
                "share_left_zero": float((group["best_fitness"] > 0).mean()),
                "first_nonzero_steps_min": steps.min() if len(steps) else np.nan,
                "first_nonzero_steps_median": steps.median() if len(steps) else np.nan,
                "first_nonzero_steps_max": steps.max() if len(steps) else np.nan,
                "balanced": len(balancing),
                "first_balancing_steps_min": balancing.min() if len(balancing) else np.nan,
                "first_balancing_steps_median": balancing.median() if len(balancing) else np.nan,
                "first_balancing_steps_max": balancing.max() if len(balancing) else np.nan,
                "best_fitness": float(group["best_fitness"].max()),
                "median_best_fitness": float(group["best_fitness"].median()),
                "behaviours": ", ".join(f"{k} {counts[k]}" for k in LABELS if k in counts),
                "best_upright_share": _per_rod(best, "upright_share_", ".2f"),
                "best_turns": _per_rod(best, "turns_", "+.1f"),
                "best_end_reason": best["end_reason"],
                "best_end_step": int(best["end_step"]),
                "best_cart_range": f"{best['cart_range']:.2f}",
                "seconds": seconds[name],
            }
        )
    return pd.DataFrame(rows, columns=CELL_COLUMNS)


README_BEGIN = (
    "<!-- calibration:begin (lonlib calibrate data/calibration --docs docs/calibration.md) -->"
)
README_END = "<!-- calibration:end -->"


def readme_markers(grid: str) -> tuple[str, str]:
    """The marker comments between which ``lonlib calibrate --readme`` pastes the table of
    the grid named ``grid`` (the default grid's are :data:`README_BEGIN`, :data:`README_END`)."""
    if grid == "default":
        return README_BEGIN, README_END
    return f"<!-- calibration-{grid}:begin -->", f"<!-- calibration-{grid}:end -->"


DRIFT_HEADER = "| integrator | steps |"


def calibration_block(source: str | Path, table: str, grid: str) -> str:
    """The block ``lonlib calibrate --docs`` pastes for ``grid``: a line naming the folder
    ``source``, then ``table`` (``calibration.md``). The integrator drift table does not
    depend on the grid's cells, so only the default grid's block keeps it (the docs print it
    once); what follows it (a study's table) stays."""
    if grid != "default" and DRIFT_HEADER in table:
        start = table.index(DRIFT_HEADER)
        end = table.find("\n\n", start)
        table = table[:start] + (table[end + 2 :] if end >= 0 else "")
    return f"*Generated from `{source}` by `lonlib calibrate`.*\n\n{table.strip()}\n"


def _kilo(steps: float) -> str:
    return f"{steps / 1000:.0f}k" if steps >= 1000 else f"{steps:.0f}"


def calibration_markdown(cells: pd.DataFrame, drift: pd.DataFrame) -> str:
    """The cell table and the integrator drift as Markdown (``calibration.md``, and the
    table of docs/calibration.md via ``lonlib calibrate OUT --docs docs/calibration.md``)."""

    def steps(row: pd.Series, event: str = "nonzero") -> str:
        if pd.isna(row[f"first_{event}_steps_median"]):
            return "never"
        low, mid, high = (_kilo(row[f"first_{event}_steps_{k}"]) for k in ("min", "median", "max"))
        return f"{mid} ({low}–{high})"

    lines = [
        "| motor | integrator | reward | left zero | env steps to first > 0: median (range) "
        f"| reached ≥ {BALANCING_FITNESS:g}: searches, env steps to it "
        "| best fitness (median best) | behaviours | best search's rollout: upright share (of "
        "the steps run) and full turns per rod, end |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for _, row in cells.iterrows():
        if row["motor"] != "velocity":
            motor = f"{row['motor']} × {row['motor_gain']:g}"
        elif pd.isna(row["motor_gain"]):
            motor = f"velocity, τ = {row['motor_tau']:g} s"
        else:
            motor = f"velocity × {row['motor_gain']:g}, τ = {row['motor_tau']:g} s"
        end = "survives" if row["best_end_reason"] == "step_limit" else row["best_end_reason"]
        start = re.search(r"_(upright-start|start[^_]+)", str(row["cell"]))
        kinds = [start.group(1)] if start else []
        kinds += [k for k in ("explore", "continue") if f"_{k}" in str(row["cell"])]
        reward = row["reward"] + (f" ({', '.join(kinds)})" if kinds else "")
        lines.append(
            f"| {motor} | {row['integrator']} | {reward} "
            f"| {row['left_zero']} of {row['searches']} | {steps(row)} "
            f"| {row['balanced']} of {row['searches']}"
            + (f", {steps(row, 'balancing')} " if row["balanced"] else " ")
            + f"| {row['best_fitness']:.3f} ({row['median_best_fitness']:.3f}) "
            f"| {row['behaviours']} | upright {row['best_upright_share'].replace(' / ', ', ')}; "
            f"turns {row['best_turns'].replace(' / ', ', ')}; {end} at {row['best_end_step']} |"
        )
    lines += ["", "| integrator | " + " | ".join(drift.columns[1:]) + " |"]
    lines.append("|---" * len(drift.columns) + "|")
    for _, row in drift.iterrows():
        values = [f"{v:.3g}" if isinstance(v, float) else str(v) for v in row.iloc[1:]]
        lines.append(f"| {row.iloc[0]} | " + " | ".join(values) + " |")
    return "\n".join(lines) + "\n"


@dataclass
class CalibrationResult:
    """What :func:`run_calibration` wrote: the tables, the figure and the file paths."""

    cells: pd.DataFrame
    searches: pd.DataFrame
    drift: pd.DataFrame
    figure: plt.Figure
    files: list[Path]


def write_outputs(
    config: CalibrationConfig, out: str | Path, stored_only: bool = False
) -> CalibrationResult:
    """Build the tables and figure from the stored cells and write them into ``out``.

    Every cell must be stored, or with ``stored_only`` at least one: the tables then hold
    the stored cells and ``calibration.md`` names the cells not finished yet (a study that
    runs across sessions reports what it has)."""
    out = Path(out)
    records = [read_cell(out, cell, config) for cell in config.cells]
    missing = [cell.name for cell, record in zip(config.cells, records, strict=True) if not record]
    if missing and (not stored_only or len(missing) == len(records)):
        raise ValueError(f"{out}: cells not finished yet: {missing}")
    records = [record for record in records if record]
    searches = search_table(records)
    cells = cell_table(searches, records)
    drift = integrator_drift(config.env, config.drift_steps)
    figure = calibration_figure(records, searches)
    files = [out / name for name in ("calibration.csv", "searches.csv", "drift.csv")]
    for table, path in zip((cells, searches, drift), files, strict=True):
        atomic_write(path, table.to_csv(index=False).encode())
    markdown = calibration_markdown(cells, drift)
    if has_judged(searches):  # the learner-side study's table, figure and curves
        study = study_table(searches)
        best = best_so_far_table(records)
        for table, name in ((study, "study.csv"), (best, "best_so_far.csv")):
            files.append(out / name)
            atomic_write(files[-1], table.to_csv(index=False).encode())
        markdown += "\n" + study_markdown(study)
        files.append(out / "study.png")
        curves = study_figure(best)
        atomic_write(files[-1], png_bytes(curves))
        plt.close(curves)
    if missing:  # first: a docs block keeps what comes before the drift table
        names = ", ".join(f"`{name}`" for name in missing)
        markdown = f"*Cells not finished yet: {names}.*\n\n{markdown}"
    files.append(out / "calibration.md")
    atomic_write(files[-1], markdown.encode())
    png = out / "calibration.png"
    atomic_write(png, png_bytes(figure))
    reseal_files_if_sealed(out)
    return CalibrationResult(cells, searches, drift, figure, [*files, png])


def calibration_figure(records: list[dict[str, Any]], searches: pd.DataFrame) -> plt.Figure:
    """The calibration study's figure. Left: best greedy fitness of every search per cell
    (a point per search, the share of searches that left zero beside). Right: the best
    greedy fitness so far against env steps, one line per search, one colour per cell."""
    names = [record["name"] for record in records]
    palette = dict(zip(names, sns.color_palette("tab20", max(len(names), 2)), strict=False))
    curves = pd.DataFrame(
        [
            {"cell": record["name"], "search": i, "env steps": step, "best so far": best}
            for record in records
            for i, search in enumerate(record["searches"])
            for step, best in zip(
                np.asarray(search["history_env_steps"], dtype=float),
                np.fmax.accumulate(np.asarray(search["history_greedy_fitness"], dtype=float)),
                strict=True,
            )
        ],
        columns=["cell", "search", "env steps", "best so far"],
    )
    with themed():
        fig, (left, right) = plt.subplots(
            1, 2, figsize=(13, max(3.5, 1.5 + 0.4 * len(names))),
            gridspec_kw={"width_ratios": [1, 1]},
        )  # fmt: skip
        points = searches[searches["cell"].isin(names)]
        sns.stripplot(
            data=points, x="best_fitness", y="cell", order=names, hue="cell", hue_order=names,
            palette=palette, jitter=False, dodge=False, size=5, legend=False, ax=left,
        )  # fmt: skip
        for row, name in enumerate(names):
            share = (points.loc[points["cell"] == name, "best_fitness"] > 0).mean()
            left.annotate(f"{share:.0%} left 0", (1.0, row), fontsize=7, va="center", ha="right")
        left.set_xlim(-0.02, 1.02)
        left.set_xlabel("best greedy fitness per search")
        left.set_ylabel("")
        if len(curves):
            sns.lineplot(
                data=curves, x="env steps", y="best so far", hue="cell", hue_order=names,
                units="search", estimator=None, palette=palette, drawstyle="steps-post",
                linewidth=1, ax=right,
            )  # fmt: skip
            right.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False)
        right.set_xlabel("environment steps")
        right.xaxis.set_major_formatter(plt.FuncFormatter(lambda v, _: f"{v / 1000:g}k"))
        right.set_ylabel("best greedy fitness so far")
        fig.suptitle("Calibration: which physics lets DDPG leave zero")
        fig.tight_layout()
    return fig
