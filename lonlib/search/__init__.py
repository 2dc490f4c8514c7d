"""The global search: parameter-level basin hopping (paper Algorithm 2)."""

from lonlib.search.algorithm import (
    AcceptTest,
    BasinHoppingRun,
    LocalOptimum,
    LocalSearch,
    RunState,
    SearchRequest,
    Trial,
    basin_hopping,
    basin_hopping_steps,
    perturb_parameters,
    random_networks,
    random_parameters,
)

__all__ = [
    "AcceptTest",
    "BasinHoppingRun",
    "LocalOptimum",
    "LocalSearch",
    "RunState",
    "SearchRequest",
    "Trial",
    "basin_hopping",
    "basin_hopping_steps",
    "perturb_parameters",
    "random_networks",
    "random_parameters",
]
