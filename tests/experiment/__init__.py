"""lonlib.experiment: runs, executors (lockstep), in-flight checkpoints, draining, faults."""
