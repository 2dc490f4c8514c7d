"""One look for every statistical figure, and PNG files that are byte-stable.

:func:`themed` draws with seaborn's whitegrid style at paper scale (:data:`THEME`);
:func:`png_bytes` and :func:`save_png` write PNGs at a fixed resolution with no software
version in their metadata, so the same data give the same bytes. The analysis figures
(:mod:`lonlib.analysis.plots`) and the calibration figure (:mod:`lonlib.calibration.report`)
both draw through here.
"""

from __future__ import annotations

import io
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import matplotlib.pyplot as plt
import seaborn as sns

# The one theme of the statistical figures (seaborn's whitegrid at paper scale) and the PNG
# settings that keep a figure's file byte-stable for the same data (no software version).
THEME = {"style": "whitegrid", "context": "paper", "font_scale": 1.1}
DPI = 120
PNG_METADATA = {"Software": None}

__all__ = ["DPI", "PNG_METADATA", "THEME", "png_bytes", "save_png", "themed"]


@contextmanager
def themed() -> Iterator[None]:
    """Draw inside this block with the figures' one theme (:data:`THEME`); matplotlib's
    global settings are left as they were."""
    with (
        sns.axes_style(THEME["style"]),
        sns.plotting_context(THEME["context"], font_scale=THEME["font_scale"]),
    ):
        yield


def png_bytes(fig: plt.Figure) -> bytes:
    """The figure as PNG bytes: fixed resolution, no software version in the metadata, so
    the same data give the same bytes."""
    buffer = io.BytesIO()
    fig.savefig(buffer, dpi=DPI, format="png", metadata=PNG_METADATA)
    return buffer.getvalue()


def save_png(fig: plt.Figure, path: str | Path) -> Path:
    """Write the figure as a byte-stable PNG (:func:`png_bytes`)."""
    path = Path(path)
    path.write_bytes(png_bytes(fig))
    return path
