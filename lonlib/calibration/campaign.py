"""The calibration study run end to end: every unfinished cell (:mod:`lonlib.calibration.study`),
then its report (:mod:`lonlib.calibration.report`) from the cells stored
(:mod:`lonlib.calibration.cell_store`)."""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
from datetime import UTC, datetime
from pathlib import Path

from lonlib.calibration.cell_store import read_cell
from lonlib.calibration.report import CalibrationResult, write_outputs
from lonlib.calibration.study import cell_starts, run_and_store_cell
from lonlib.config import CalibrationConfig
from lonlib.storage.atomic import atomic_write, write_json
from lonlib.storage.digests import reseal_files_if_sealed
from lonlib.util.progress import progress_bar
from lonlib.util.validation import check_range

# What a study folder keeps out of git (data/studies/ is committed): the Actors and Critics
# and the in-flight checkpoints; the records, tables and figures are small.
GITIGNORE = "*.npz\ninflight/\n.*.tmp\n"


def gitignore_text(config: CalibrationConfig) -> str:
    """The study folder's ``.gitignore``: :data:`GITIGNORE`, except the Actors and Critics of
    the cells a ``continue_from`` cell starts from (a few tens of KB each): committed, they
    let that cell run in a later session, on another machine, than the cell it continues."""
    sources = dict.fromkeys(c.continue_from for c in config.cells if c.continue_from)
    return GITIGNORE + "".join(f"!{name}.npz\n" for name in sources)


def run_calibration(
    config: CalibrationConfig,
    out: str | Path,
    workers: int = 1,
    progress: bool = True,
    checkpoint_seconds: float = 600.0,
    check_steps: int = 1000,
) -> CalibrationResult:
    """Run every unfinished cell of ``config`` into ``out`` and write the tables and figure.

    ``workers`` > 1 runs cells in that many processes (one torch thread each; more workers
    than unfinished cells are not started); cells that continue from another cell's
    searches (``continue_from``) run after the others. Finished cells are read back, not
    recomputed; a cell in flight continues from its checkpoint (written every
    ``checkpoint_seconds``, looked at every ``check_steps`` env steps;
    :func:`lonlib.calibration.study.run_cell`). A folder holding
    cells computed with other settings is refused before any compute. ``progress``: a bar
    of the cells and, from each cell, a line a minute (env steps per search, env steps/s).
    """
    check_range("workers", workers, 1, 4096)
    check_range("checkpoint_seconds", checkpoint_seconds, 0.0)
    out = Path(out)
    todo = [cell for cell in config.cells if read_cell(out, cell, config) is None]
    for cell in todo:  # a source stored before the study kept its Critics: refused now
        if cell.continue_from and config.cell(cell.continue_from) not in todo:
            cell_starts(cell, config, out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / ".gitignore", gitignore_text(config).encode())
    write_json(
        out / "calibration.json",
        {"config": config.to_dict(), "updated": datetime.now(UTC).isoformat(timespec="seconds")},
    )
    reseal_files_if_sealed(out)
    bar = progress_bar(
        total=len(config.cells),
        initial=len(config.cells) - len(todo),
        desc=f"calibration {config.name}",
        unit="cell",
        disable=not progress,
    )
    try:
        options = {
            "checkpoint_seconds": checkpoint_seconds,
            "progress": progress,
            "check_steps": check_steps,
        }
        waves = [
            [cell for cell in todo if not cell.continue_from],
            [cell for cell in todo if cell.continue_from],
        ]
        for wave in waves:
            if workers <= 1 or len(wave) <= 1:
                for cell in wave:
                    bar.set_postfix_str(cell.name)
                    run_and_store_cell(out, cell, config, **options)
                    bar.update(1)
                continue
            context = multiprocessing.get_context("spawn")
            with cf.ProcessPoolExecutor(min(workers, len(wave)), mp_context=context) as pool:
                futures = [
                    pool.submit(run_and_store_cell, out, cell, config, **options) for cell in wave
                ]
                for future in cf.as_completed(futures):
                    bar.set_postfix_str(future.result())
                    bar.update(1)
    finally:
        bar.close()
    return write_outputs(config, out)
