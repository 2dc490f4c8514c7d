"""The calibration study of the physics and its report."""

from lonlib.calibration.campaign import run_calibration
from lonlib.calibration.report import (
    CalibrationResult,
    calibration_figure,
    calibration_markdown,
    write_outputs,
)
from lonlib.calibration.study import (
    DEFAULT_CELLS,
    CalibrationConfig,
    Cell,
    StartSpread,
    grid,
    load_calibration,
    named_calibration,
    run_cell,
    with_overrides,
)

__all__ = [
    "CalibrationConfig",
    "CalibrationResult",
    "Cell",
    "DEFAULT_CELLS",
    "StartSpread",
    "calibration_figure",
    "calibration_markdown",
    "grid",
    "load_calibration",
    "named_calibration",
    "run_calibration",
    "run_cell",
    "with_overrides",
    "write_outputs",
]
