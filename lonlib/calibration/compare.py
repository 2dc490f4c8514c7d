"""Best-so-far curves of cells stored in several study folders, in one figure: the geometry
cells beside the learner-side study's default cell (docs/study-geometry.md).

``python -m lonlib.calibration.compare OUT.png LABEL=FOLDER[:CELL] ...`` draws them."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd

from lonlib.calibration.report import study_figure
from lonlib.storage.atomic import atomic_write
from lonlib.util.figures import png_bytes


def best_so_far_across(cells: Sequence[tuple[str, Path, str | None]]) -> pd.DataFrame:
    """The best-so-far table (``best_so_far.csv``, :func:`lonlib.calibration.report.
    best_so_far_table`) of each ``(label, folder, cell)``: that cell's searches (every cell of
    the folder when ``cell`` is None), their ``cell`` column renamed ``label`` (with the
    cell's name when the folder's cells are all kept). ValueError naming a folder without
    the table or a cell it does not hold."""
    parts = []
    for label, folder, cell in cells:
        path = Path(folder) / "best_so_far.csv"
        if not path.is_file():
            raise ValueError(
                f"{path}: no best-so-far table (run `lonlib calibrate ... --stored-only`)"
            )
        table = pd.read_csv(path)
        if cell is not None:
            if cell not in set(table["cell"]):
                raise ValueError(
                    f"{path}: holds no cell {cell!r} (it holds {sorted(set(table['cell']))})"
                )
            table = table[table["cell"] == cell].assign(cell=label)
        else:
            table = table.assign(cell=label + ": " + table["cell"])
        parts.append(table)
    return pd.concat(parts, ignore_index=True)


def comparison_figure(cells: Sequence[tuple[str, Path, str | None]]) -> plt.Figure:
    """:func:`lonlib.calibration.report.study_figure` of :func:`best_so_far_across`."""
    fig = study_figure(best_so_far_across(cells))
    fig.suptitle("Best greedy fitness so far per search, cells of several study folders")
    return fig


def _cell_argument(text: str) -> tuple[str, Path, str | None]:
    label, sep, where = text.partition("=")
    if not sep or not label or not where:
        raise argparse.ArgumentTypeError(f"expected LABEL=FOLDER[:CELL], got {text!r}")
    folder, _, cell = where.partition(":")
    return label, Path(folder), cell or None


def main(argv: Sequence[str] | None = None) -> None:
    """Write the comparison figure (PNG) of the cells given on the command line."""
    parser = argparse.ArgumentParser(prog="python -m lonlib.calibration.compare")
    parser.add_argument("out", type=Path, help="the PNG to write")
    parser.add_argument("cells", nargs="+", type=_cell_argument, help="LABEL=FOLDER[:CELL]")
    args = parser.parse_args(argv)
    fig = comparison_figure(args.cells)
    atomic_write(args.out, png_bytes(fig))
    plt.close(fig)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
