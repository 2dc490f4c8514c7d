"""The calibration study's report: tables, Markdown and figure from its stored cells.

:func:`write_outputs` reads the cells :func:`lonlib.calibration.study.run_calibration` stored and
writes ``calibration.csv`` (one row per cell, :func:`cell_table`), ``searches.csv`` (one row
per search, :func:`search_table`), ``drift.csv``
(:func:`lonlib.calibration.study.integrator_drift`), ``calibration.md``
(:func:`calibration_markdown`, the table of docs/calibration.md) and ``calibration.png``
(:func:`calibration_figure`, drawn with seaborn under the figures' one theme).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import seaborn as sns

from lonlib.calibration.study import (
    BALANCING_FITNESS,
    CELL_COLUMNS,
    CalibrationConfig,
    history_summary,
    integrator_drift,
    read_cell,
)
from lonlib.storage.store import atomic_write
from lonlib.task.behaviour import LABELS
from lonlib.util.figures import png_bytes, themed


def search_table(records: list[dict[str, Any]]) -> pd.DataFrame:
    """One row per search: the cell's settings, fitness, steps to the first non-zero
    greedy fitness and the greedy rollout of the returned Actor."""
    rows = []
    for record in records:
        for search in record["searches"]:
            row = {"cell": record["name"], **record["cell"]}
            # only the velocity motor has a time constant, only the others a gain
            row["motor_gain" if row["motor"] == "velocity" else "motor_tau"] = np.nan
            row.update({k: v for k, v in search.items() if not k.startswith("history_")})
            # from the history, so that records stored before NaN-safe summaries read right
            row.update(
                history_summary(search["history_env_steps"], search["history_greedy_fitness"])
            )
            rows.append(row)
    table = pd.DataFrame(rows)
    for column in ("first_nonzero_steps", "first_balancing_steps"):
        table[column] = table[column].astype("float64")
    return table


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
    once)."""
    if grid != "default" and DRIFT_HEADER in table:
        table = table[: table.index(DRIFT_HEADER)]
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
        motor = (
            f"velocity, τ = {row['motor_tau']:g} s"
            if row["motor"] == "velocity"
            else f"{row['motor']} × {row['motor_gain']:g}"
        )
        end = "survives" if row["best_end_reason"] == "step_limit" else row["best_end_reason"]
        lines.append(
            f"| {motor} | {row['integrator']} | {row['reward']} "
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


def write_outputs(config: CalibrationConfig, out: str | Path) -> CalibrationResult:
    """Build the tables and figure from the stored cells and write them into ``out``."""
    out = Path(out)
    records = [read_cell(out, cell, config) for cell in config.cells]
    missing = [cell.name for cell, record in zip(config.cells, records, strict=True) if not record]
    if missing:
        raise ValueError(f"{out}: cells not finished yet: {missing}")
    searches = search_table(records)
    cells = cell_table(searches, records)
    drift = integrator_drift(config.env, config.drift_steps)
    figure = calibration_figure(records, searches)
    files = [out / name for name in ("calibration.csv", "searches.csv", "drift.csv")]
    for table, path in zip((cells, searches, drift), files, strict=True):
        atomic_write(path, table.to_csv(index=False).encode())
    files.append(out / "calibration.md")
    atomic_write(files[-1], calibration_markdown(cells, drift).encode())
    png = out / "calibration.png"
    atomic_write(png, png_bytes(figure))
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
