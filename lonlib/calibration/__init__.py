"""The calibration study of the physics and its report."""

from lonlib.calibration.campaign import run_calibration
from lonlib.calibration.report import (
    CalibrationResult,
    calibration_figure,
    calibration_markdown,
    write_outputs,
)
from lonlib.calibration.study import run_cell

__all__ = [
    "CalibrationResult",
    "calibration_figure",
    "calibration_markdown",
    "run_calibration",
    "run_cell",
    "write_outputs",
]
