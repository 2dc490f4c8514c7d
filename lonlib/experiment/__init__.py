"""Running experiments: executors, the lockstep batch, in-flight checkpoints, resumable runs."""

from lonlib.experiment.running import *  # noqa: F403
