"""Peaks of fitness histograms (the paper's Figures 4 and 5 report five of them)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks

PAPER_PEAKS = (0.22, 0.32, 0.46, 0.55, 0.72)


def detect_peaks(
    values: np.ndarray,
    bins: int = 50,
    value_range: tuple[float, float] = (0.0, 1.0),
    smoothing: float = 1.0,
    min_prominence: float = 0.05,
) -> pd.DataFrame:
    """Local maxima of the histogram of ``values``.

    The counts are smoothed with a Gaussian of ``smoothing`` bins (0: none) and a peak must
    stand out by at least ``min_prominence`` of the tallest bin (and by one count). Returns
    one row per peak: ``fitness`` (bin centre), ``count`` (raw count in that bin),
    ``prominence``.
    """
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    counts, edges = np.histogram(values, bins=bins, range=value_range)
    centres = 0.5 * (edges[:-1] + edges[1:])
    if not counts.any():
        return pd.DataFrame(columns=["fitness", "count", "prominence"])
    smooth = gaussian_filter1d(counts.astype(float), smoothing) if smoothing > 0 else counts
    # Zero padding lets a peak sit in the first or last bin.
    padded = np.concatenate([[0.0], smooth, [0.0]])
    prominence = max(min_prominence * smooth.max(), 1e-9 if smoothing > 0 else 1.0)
    index, props = find_peaks(padded, prominence=prominence)
    index = index - 1
    return pd.DataFrame(
        {"fitness": centres[index], "count": counts[index], "prominence": props["prominences"]}
    )


def compare_with_paper(peaks: pd.DataFrame, paper: tuple[float, ...] = PAPER_PEAKS) -> pd.DataFrame:
    """Each paper peak beside the nearest detected peak and their distance."""
    detected = peaks["fitness"].to_numpy()
    rows = []
    for target in paper:
        if detected.size:
            nearest = float(detected[np.argmin(np.abs(detected - target))])
            rows.append(
                {
                    "paper_peak": target,
                    "nearest_detected": nearest,
                    "distance": abs(nearest - target),
                }
            )
        else:
            rows.append({"paper_peak": target, "nearest_detected": np.nan, "distance": np.nan})
    return pd.DataFrame(rows)
