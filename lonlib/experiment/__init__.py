"""Running experiments: executors, the lockstep batch, in-flight checkpoints, resumable runs."""

from lonlib.experiment.checkpoints import (
    METADATA_KEYS,
    StoredBatch,
    check_settings,
    load_inflight,
    read_inflight,
    remove_inflight,
    remove_leftovers,
    save_inflight,
    split_inflight,
)
from lonlib.experiment.executors import (
    OnDone,
    Task,
    execute_runs,
    resolve_executor,
    run_dask,
    run_pool,
    run_serial,
)
from lonlib.experiment.lockstep import (
    CHECKPOINT_SECONDS,
    LockstepBatch,
    check_lockstep,
    run_lockstep,
)
from lonlib.experiment.lockstep_workers import (
    run_lockstep_processes,
    split_jobs,
    spread_checkpoints,
)
from lonlib.experiment.running import (
    check_worker_sees_folder,
    pending_runs,
    refuse_mixed_result_paths,
    remove_finished_checkpoints,
    run_experiment,
    run_one,
    warn_about_cpu_kernels,
)
from lonlib.experiment.runs import (
    experiment_plan,
    hold_runs,
    initial_parameters,
    open_run,
    run_lock_path,
    run_summary,
)

__all__ = [
    "CHECKPOINT_SECONDS",
    "LockstepBatch",
    "METADATA_KEYS",
    "OnDone",
    "StoredBatch",
    "Task",
    "check_lockstep",
    "check_settings",
    "check_worker_sees_folder",
    "execute_runs",
    "experiment_plan",
    "hold_runs",
    "initial_parameters",
    "load_inflight",
    "open_run",
    "pending_runs",
    "read_inflight",
    "refuse_mixed_result_paths",
    "remove_finished_checkpoints",
    "remove_inflight",
    "remove_leftovers",
    "resolve_executor",
    "run_dask",
    "run_experiment",
    "run_lock_path",
    "run_lockstep",
    "run_lockstep_processes",
    "run_one",
    "run_pool",
    "run_serial",
    "run_summary",
    "save_inflight",
    "split_inflight",
    "split_jobs",
    "spread_checkpoints",
    "warn_about_cpu_kernels",
]
