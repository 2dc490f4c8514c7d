"""Cells of several study folders in one best-so-far figure (lonlib.calibration.compare)."""

from pathlib import Path

import pandas as pd
import pytest

from lonlib.calibration.compare import best_so_far_across, main

STUDIES = Path(__file__).resolve().parents[2] / "data" / "studies"
DEFAULT = "velocity-tau0.02_semi-implicit_height"


def test_the_committed_cells_come_back_under_their_labels():
    cells = [("default", STUDIES / "two-cart", DEFAULT), ("wide", STUDIES / "geometry-wide", None)]
    table = best_so_far_across(cells)
    stored = pd.read_csv(STUDIES / "two-cart" / "best_so_far.csv")
    default = table[table["cell"] == "default"].drop(columns="cell").reset_index(drop=True)
    expected = stored[stored["cell"] == DEFAULT].drop(columns="cell").reset_index(drop=True)
    pd.testing.assert_frame_equal(default, expected)
    assert {c for c in table["cell"] if c.startswith("wide: ")} == {
        f"wide: {DEFAULT}",
        f"wide: {DEFAULT}_upright-start",
    }


def test_a_cell_the_folder_does_not_hold_is_named(tmp_path):
    with pytest.raises(ValueError, match="holds no cell 'nope'"):
        best_so_far_across([("x", STUDIES / "two-cart", "nope")])
    with pytest.raises(ValueError, match="no best-so-far table"):
        best_so_far_across([("x", tmp_path, None)])


def test_the_command_writes_the_figure(tmp_path):
    out = tmp_path / "compare.png"
    main([str(out), f"default={STUDIES / 'two-cart'}:{DEFAULT}"])
    assert out.read_bytes().startswith(b"\x89PNG")
