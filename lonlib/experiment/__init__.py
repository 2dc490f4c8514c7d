"""Running experiments: executors, the lockstep batch, in-flight checkpoints, resumable runs."""

from lonlib.experiment.executors import execute_runs, resolve_executor, session_executor
from lonlib.experiment.lockstep import (
    CHECKPOINT_SECONDS,
    LockstepBatch,
    check_lockstep,
    run_lockstep,
)
from lonlib.experiment.running import pending_runs, run_experiment, run_one, status
from lonlib.experiment.runs import experiment_plan, hold_runs, open_run, run_summary

__all__ = [
    "CHECKPOINT_SECONDS",
    "LockstepBatch",
    "check_lockstep",
    "execute_runs",
    "experiment_plan",
    "hold_runs",
    "open_run",
    "pending_runs",
    "resolve_executor",
    "run_experiment",
    "run_lockstep",
    "run_one",
    "run_summary",
    "session_executor",
    "status",
]
