"""Small utilities whose mutants survived the other tests: byte-stable PNG files and the
renamed keyword arguments."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from lonlib.util.deprecation import renamed_keyword  # noqa: E402
from lonlib.util.figures import png_bytes, save_png  # noqa: E402


def test_a_saved_png_is_exactly_png_bytes_without_the_software_tag(tmp_path):
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    path = save_png(fig, tmp_path / "figure.png")
    plt.close(fig)
    data = path.read_bytes()
    assert data == png_bytes(fig)
    assert b"Matplotlib" not in data


def test_a_renamed_keyword_is_accepted_with_a_warning_and_both_are_refused():
    @renamed_keyword("tolerance", "fitness_tolerance")
    def build(fitness_tolerance: float = 0.0) -> float:
        return fitness_tolerance

    with pytest.warns(DeprecationWarning, match=r"build\(tolerance=...\) is deprecated"):
        assert build(tolerance=0.5) == 0.5
    assert build(fitness_tolerance=0.25) == 0.25
    with pytest.raises(TypeError, match="got both 'tolerance' and 'fitness_tolerance'"):
        build(tolerance=0.5, fitness_tolerance=0.25)
