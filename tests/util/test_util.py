"""Small utilities whose mutants survived the other tests: byte-stable PNG files."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402

from lonlib.util.figures import png_bytes, save_png  # noqa: E402


def test_a_saved_png_is_exactly_png_bytes_without_the_software_tag(tmp_path):
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    path = save_png(fig, tmp_path / "figure.png")
    plt.close(fig)
    data = path.read_bytes()
    assert data == png_bytes(fig)
    assert b"Matplotlib" not in data
