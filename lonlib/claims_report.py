"""The claims table (:mod:`lonlib.claims`) as Markdown and as files beside the figures."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from lonlib.readme_tables import splice_generated
from lonlib.store import p_label

CLAIM_COLUMNS = {"claim": "claim", "paper": "the paper says", "evidence": "evidence"}
PEAK_COLUMNS = ("paper_peak", "nearest_detected", "distance")
README_BEGIN = "<!-- claims:begin (lonlib analyse data/reference --readme README.md) -->"
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


def claims_markdown(claims: pd.DataFrame, peaks: pd.DataFrame | None = None) -> str:
    """The claims table as Markdown (claim, the paper's words, p, evidence, verdict in
    bold), then the paper's peaks beside the nearest detected ones when ``peaks`` (from
    :func:`lonlib.claims.peaks_beside_paper`) is given."""
    table = pd.DataFrame(
        {
            "claim": claims["claim"],
            "the paper says": ["“" + text + "”" for text in claims["paper"]],
            "p": [p_label(p) if not math.isnan(p) else "1e-4 vs 1e-3" for p in claims["p"]],
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
    return "\n\n".join(parts) + "\n"


def write_claims(claims: pd.DataFrame, peaks: pd.DataFrame | None, out: str | Path) -> list[Path]:
    """Write ``claims.csv`` (every column) and ``claims.md`` (:func:`claims_markdown`)
    into the folder ``out`` (created if missing); the paths written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    csv, md = out / "claims.csv", out / "claims.md"
    claims.to_csv(csv, index=False)
    md.write_text(claims_markdown(claims, peaks), encoding="utf-8")
    return [csv, md]


def splice_readme(readme: str, markdown: str, source: str) -> str:
    """``readme`` with the text between :data:`README_BEGIN` and :data:`README_END`
    replaced by ``markdown`` and a line naming the experiment folder ``source`` it came
    from, so the README's claims table is generated, never typed."""
    return splice_generated(readme, README_BEGIN, README_END, markdown, source)
