"""The calibration study of the physics and its report."""

from lonlib.calibration.campaign import (
    run_calibration,
)
from lonlib.calibration.report import (
    README_BEGIN,
    README_END,
    CalibrationResult,
    calibration_figure,
    calibration_markdown,
    cell_table,
    readme_markers,
    search_table,
    write_outputs,
)
from lonlib.calibration.study import (
    CELL_COLUMNS,
    DEFAULT_CELLS,
    CalibrationConfig,
    Cell,
    StartSpread,
    greedy_rollout,
    grid,
    integrator_drift,
    judged_summary,
    load_calibration,
    named_calibration,
    run_cell,
    with_overrides,
)

__all__ = [
    "CELL_COLUMNS",
    "CalibrationConfig",
    "CalibrationResult",
    "Cell",
    "DEFAULT_CELLS",
    "README_BEGIN",
    "README_END",
    "StartSpread",
    "calibration_figure",
    "calibration_markdown",
    "cell_table",
    "greedy_rollout",
    "grid",
    "integrator_drift",
    "judged_summary",
    "load_calibration",
    "named_calibration",
    "readme_markers",
    "run_calibration",
    "run_cell",
    "search_table",
    "with_overrides",
    "write_outputs",
]
