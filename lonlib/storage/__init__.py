"""What an experiment stores and how it is read back (no torch): the folder
layout, atomic storage of runs, the manifest, locks, provenance and the result-path version."""

from lonlib.storage.atomic import (
    CorruptDataError,
    DataWriteError,
    MissingExperimentError,
    read_json,
    write_json,
)
from lonlib.storage.layout import history_path, optimum_path, read_manifest, run_dir, trials_path
from lonlib.storage.lock import LockHeld
from lonlib.storage.manifest import manifest_path, session_seconds
from lonlib.storage.policies import StoredPolicy, load_policy
from lonlib.storage.result_path import RESULT_PATH_VERSION, experiment_digest
from lonlib.storage.session import SamplingSession
from lonlib.storage.status import experiment_status
from lonlib.storage.thin import thin_histories
from lonlib.storage.trials import (
    read_experiment_trials,
    read_finished_trials,
    read_optimum,
    read_trials,
)

__all__ = [
    "CorruptDataError",
    "DataWriteError",
    "LockHeld",
    "MissingExperimentError",
    "RESULT_PATH_VERSION",
    "SamplingSession",
    "StoredPolicy",
    "experiment_digest",
    "experiment_status",
    "history_path",
    "load_policy",
    "manifest_path",
    "optimum_path",
    "read_experiment_trials",
    "read_finished_trials",
    "read_json",
    "read_manifest",
    "read_optimum",
    "read_trials",
    "run_dir",
    "session_seconds",
    "thin_histories",
    "trials_path",
    "write_json",
]
