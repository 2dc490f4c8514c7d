"""Resumable, atomic storage of basin-hopping runs under ``data/<experiment>/``.

What lived here is now three modules, re-exported: :mod:`lonlib.storage.atomic` (atomic
file I/O and its errors), :mod:`lonlib.storage.layout` (the folder layout, in one place)
and :mod:`lonlib.storage.trials` (the trial schema and the run state replayed from it).
"""

from lonlib.storage.atomic import (  # noqa: F401
    TEMPORARY_SUFFIX,
    CorruptDataError,
    DataWriteError,
    MissingExperimentError,
    atomic_write,
    check_output_folder,
    parquet_bytes,
    read_json,
    remove_temporary_files,
    temporary_files,
    write_error,
    write_json,
)
from lonlib.storage.layout import (  # noqa: F401
    Job,
    history_path,
    optimum_path,
    p_label,
    read_manifest,
    run_dir,
    trials_path,
)
from lonlib.storage.trials import (  # noqa: F401
    TRIAL_COLUMNS,
    TRIAL_FIELDS,
    load_run_state,
    read_experiment_trials,
    read_finished_trials,
    read_optimum,
    read_trials,
    replay_trials,
    save_step,
    trials_frame,
)
