"""The global search: parameter-level basin hopping (paper Algorithm 2)."""

from lonlib.search.algorithm import (
    AcceptTest,
    BasinHoppingConfig,
    BasinHoppingRun,
    LocalOptimum,
    LocalSearch,
    RunState,
    SearchRequest,
    TakeStep,
    Trial,
    TrialSeeds,
    basin_hopping,
    basin_hopping_steps,
    non_deteriorating,
    perturb,
    perturb_parameters,
    trial_seeds,
)

__all__ = [
    "AcceptTest",
    "BasinHoppingConfig",
    "BasinHoppingRun",
    "LocalOptimum",
    "LocalSearch",
    "RunState",
    "SearchRequest",
    "TakeStep",
    "Trial",
    "TrialSeeds",
    "basin_hopping",
    "basin_hopping_steps",
    "non_deteriorating",
    "perturb",
    "perturb_parameters",
    "trial_seeds",
]
