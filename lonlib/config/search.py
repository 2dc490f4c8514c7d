"""Algorithm 2's configuration: the perturbation strength ``p``, the tolerance ``T`` and a
budget (the algorithm itself: :mod:`lonlib.search.algorithm`)."""

from __future__ import annotations

from dataclasses import dataclass

from lonlib.util.validation import check_field_types, check_range


@dataclass(frozen=True)
class BasinHoppingConfig:
    """Algorithm 2's inputs: perturbation strength ``p``, tolerance ``T``, a budget."""

    perturbation: float = 1e-4
    """``p``: every parameter of the incumbent gets U[-p, p] before a local search."""
    tolerance: int = 5
    """``T``: the run ends after this many consecutive failures (rejections)."""
    max_local_searches: int = 100
    """Budget: the run ends after this many local searches in all."""

    def __post_init__(self) -> None:
        check_field_types(self)
        check_range("perturbation", self.perturbation, 0.0, 10.0, low_open=True)
        check_range("tolerance", self.tolerance, 1, 10_000)
        check_range("max_local_searches", self.max_local_searches, 1, 1_000_000)
