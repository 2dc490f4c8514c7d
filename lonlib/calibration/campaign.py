"""The calibration study run end to end: every unfinished cell (:mod:`lonlib.calibration.study`),
then its report (:mod:`lonlib.calibration.report`) from the cells stored."""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
from datetime import UTC, datetime
from pathlib import Path

from lonlib.calibration.report import CalibrationResult, write_outputs
from lonlib.calibration.study import CalibrationConfig, read_cell, run_and_store_cell
from lonlib.storage.store import write_json
from lonlib.util.progress import progress_bar
from lonlib.util.validation import check_range


def run_calibration(
    config: CalibrationConfig, out: str | Path, workers: int = 1, progress: bool = True
) -> CalibrationResult:
    """Run every unfinished cell of ``config`` into ``out`` and write the tables and figure.

    ``workers`` > 1 runs cells in that many processes (one torch thread each; more workers
    than unfinished cells are not started). Finished cells are read back, not recomputed;
    a folder holding cells computed with other settings is refused before any compute.
    """
    check_range("workers", workers, 1, 4096)
    out = Path(out)
    todo = [cell for cell in config.cells if read_cell(out, cell, config) is None]
    write_json(
        out / "calibration.json",
        {"config": config.to_dict(), "updated": datetime.now(UTC).isoformat(timespec="seconds")},
    )
    bar = progress_bar(
        total=len(config.cells),
        initial=len(config.cells) - len(todo),
        desc=f"calibration {config.name}",
        unit="cell",
        disable=not progress,
    )
    try:
        if workers <= 1 or len(todo) <= 1:
            for cell in todo:
                run_and_store_cell(out, cell, config)
                bar.update(1)
        else:
            context = multiprocessing.get_context("spawn")
            with cf.ProcessPoolExecutor(min(workers, len(todo)), mp_context=context) as pool:
                futures = [pool.submit(run_and_store_cell, out, cell, config) for cell in todo]
                for future in cf.as_completed(futures):
                    bar.set_postfix_str(future.result())
                    bar.update(1)
    finally:
        bar.close()
    return write_outputs(config, out)
