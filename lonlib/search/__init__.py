"""The global search: parameter-level basin hopping (paper Algorithm 2)."""

from lonlib.search.algorithm import (
    BasinHoppingConfig,
    BasinHoppingRun,
    LocalOptimum,
    LocalSearch,
    RunState,
    SearchRequest,
    Trial,
    TrialSeeds,
    basin_hopping,
    basin_hopping_steps,
    perturb,
    trial_seeds,
)

__all__ = [
    "BasinHoppingConfig",
    "BasinHoppingRun",
    "LocalOptimum",
    "LocalSearch",
    "RunState",
    "SearchRequest",
    "Trial",
    "TrialSeeds",
    "basin_hopping",
    "basin_hopping_steps",
    "perturb",
    "trial_seeds",
]
