"""The claims table (:mod:`lonlib.analysis.claims`) as Markdown and as files beside the figures."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from lonlib.util.labels import p_label
from lonlib.util.readme_tables import splice_generated

CLAIM_COLUMNS = {"claim": "claim", "paper": "the paper says", "evidence": "evidence"}
PEAK_COLUMNS = ("paper_peak", "nearest_detected", "distance")
README_BEGIN = "<!-- claims:begin (lonlib analyse data/reference --docs docs/results.md) -->"
README_END = "<!-- claims:end -->"


def cell(value: object) -> str:
    """One Markdown table cell: numbers to 4 significant digits, NaN empty, pipes escaped,
    line breaks flattened."""
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.4g}"
    return str(value).replace("|", "\\|").replace("\n", " ")


def markdown_table(frame: pd.DataFrame) -> str:
    """A pipe table of ``frame`` (its column names as the header)."""
    lines = ["| " + " | ".join(cell(c) for c in frame.columns) + " |"]
    lines.append("|" + "---|" * len(frame.columns))
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in frame.itertuples(False)]
    return "\n".join(lines)


def _statistic(row) -> str:
    if isinstance(row.statistic, float) and math.isnan(row.statistic):
        return ""
    return f"{row.statistic_name} = {cell(float(row.statistic))}"


def _effect(row) -> str:
    if isinstance(row.effect, float) and math.isnan(row.effect):
        return ""
    interval = f" [{cell(float(row.ci_low))}, {cell(float(row.ci_high))}]"
    return f"{row.measure}: {cell(float(row.effect))}{interval}; paper: {row.direction}"


CURVE_EPSILONS = (0.1, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0)
"""The epsilons of claim d's curve shown in ``claims.md`` (``claim_d_curve.csv`` has all)."""


def curve_markdown(curve: pd.DataFrame, epsilons=CURVE_EPSILONS) -> str:
    """Claim d's curve as a table: one row per p, per epsilon "multi-inward / nodes"."""
    shown = curve[np.isin(curve["epsilon"].round(6), np.round(epsilons, 6))]
    table = {"p": []} | {f"ε = {e:g}": [] for e in epsilons}
    for p, group in shown.groupby("p", sort=True):
        table["p"].append(p_label(p))
        by = dict(zip(group["epsilon"].round(6), group.itertuples(False), strict=True))
        for e in epsilons:
            row = by.get(round(e, 6))
            cells = f"{row.multi_inward} / {row.nodes}" if row is not None else ""
            table[f"ε = {e:g}"].append(cells)
    return markdown_table(pd.DataFrame(table))


def power_markdown(power: pd.DataFrame) -> str:
    """The power table (:func:`lonlib.analysis.claims_power.power_table`) as Markdown: per claim the
    smallest effect of interest, what it needs, and the cost of both p at that scale."""
    table = pd.DataFrame(
        {
            "claim": power["claim"],
            "smallest effect of interest": power["effect_of_interest"],
            "power from": power["method"],
            "needed for 80 % power": [
                f"{n} {u}" for n, u in zip(power["units_needed"], power["unit"], strict=True)
            ],
            "runs per p": power["runs_per_p"],
            "env steps, both p (M)": [f"{v:.0f}" for v in power["env_steps_M"]],
            "this machine (h, 2 cores, measured rate)": [
                f"{v:.0f}" for v in power["this_machine_hours"]
            ],
            "64-core Dask (h, extrapolated)": [f"{v:.1f}" for v in power["dask_64_hours"]],
            "one GPU (h, H200 early-training rate)": [f"{v:.1f}" for v in power["gpu_hours"]],
        }
    )
    return markdown_table(table)


def claims_markdown(
    claims: pd.DataFrame,
    peaks: pd.DataFrame | None = None,
    power: pd.DataFrame | None = None,
    curve: pd.DataFrame | None = None,
) -> str:
    """The claims table as Markdown (claim, the paper's words, p, n, the statistic, the
    effect with its interval and the paper's side, evidence, verdict in bold), then the
    paper's peaks beside the nearest detected ones when ``peaks`` (from
    :func:`lonlib.analysis.claims.peaks_beside_paper`) is given, claim d's curve over epsilon when
    ``curve`` (:func:`lonlib.analysis.claims.claim_d_curve`) is given and not empty, and the power
    table when ``power`` (:func:`lonlib.analysis.claims_power.power_table`) is given."""
    table = pd.DataFrame(
        {
            "claim": claims["claim"],
            "the paper says": ["“" + text + "”" for text in claims["paper"]],
            "p": [p_label(p) if not math.isnan(p) else "1e-4 vs 1e-3" for p in claims["p"]],
            "n": claims["n"],
            "statistic": [_statistic(row) for row in claims.itertuples(False)],
            "effect [90 % interval]": [_effect(row) for row in claims.itertuples(False)],
            "evidence": claims["evidence"],
            "verdict": ["**" + v + "**" for v in claims["verdict"]],
        }
    )
    parts = [markdown_table(table)]
    if peaks is not None and not peaks.empty:
        wide = peaks.pivot(index="paper_peak", columns="histogram", values=list(PEAK_COLUMNS[1:]))
        side = pd.DataFrame({"paper peak": wide.index.to_numpy()})
        for histogram in ("sinks", "optima"):
            if ("nearest_detected", histogram) in wide:
                side[f"nearest {histogram} peak"] = wide[("nearest_detected", histogram)].to_numpy()
                side[f"distance ({histogram})"] = wide[("distance", histogram)].to_numpy()
        p = float(peaks["p"].iloc[0])
        counts = peaks.groupby("histogram")["values"].first() if "values" in peaks else {}
        singular = {"sinks": "sink", "optima": "optimum"}
        sinks, optima = (
            f", {counts[h]} {h if counts[h] != 1 else singular[h]}" if h in counts else ""
            for h in ("sinks", "optima")
        )
        parts += [
            f"Peaks at p = {p_label(p)}: the paper's beside the nearest detected in the "
            f"sink histogram (Fig. 4{sinks}) and the optima histogram (Fig. 5{optima}).",
            markdown_table(side),
        ]
    if curve is not None and not curve.empty:
        parts += [
            "Claim d over epsilon: behaviour nodes entered from more than one other node / "
            "behaviour nodes (fitness within 0.02; `claim_d_curve.csv` has every epsilon "
            "from 0.1 to 2.0 and the intervals).",
            curve_markdown(curve),
        ]
    if power is not None and not power.empty:
        parts += [
            "Runs needed to detect each claim's smallest effect of interest with 80 % power "
            "at one-sided alpha 0.05, and the cost of running both p at that scale "
            "(`power.csv`; `lonlib.analysis.claims_power` says what is measured, extrapolated and "
            "estimated).",
            power_markdown(power),
        ]
    return "\n\n".join(parts) + "\n"


def write_claims(
    claims: pd.DataFrame,
    peaks: pd.DataFrame | None,
    out: str | Path,
    power: pd.DataFrame | None = None,
    curve: pd.DataFrame | None = None,
) -> list[Path]:
    """Write ``claims.csv`` (every column) and ``claims.md`` (:func:`claims_markdown`)
    into the folder ``out`` (created if missing), and ``power.csv`` and
    ``claim_d_curve.csv`` when given; the paths written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    csv, md = out / "claims.csv", out / "claims.md"
    claims.to_csv(csv, index=False)
    md.write_text(claims_markdown(claims, peaks, power, curve), encoding="utf-8")
    written = [csv, md]
    for name, table in (("power", power), ("claim_d_curve", curve)):
        if table is not None:
            path = out / f"{name}.csv"
            table.to_csv(path, index=False)
            written.append(path)
    return written


def splice_readme(readme: str, markdown: str, source: str) -> str:
    """``readme`` with the text between :data:`README_BEGIN` and :data:`README_END`
    replaced by ``markdown`` and a line naming the experiment folder ``source`` it came
    from, so the claims table of docs/results.md is generated, never typed."""
    return splice_generated(readme, README_BEGIN, README_END, markdown, source)
