"""How a policy is scored (:class:`Scoring`): which estimate of the fitness Algorithm 2 compares
and from which starts (the rollouts themselves: :mod:`lonlib.task.rollout`)."""

from __future__ import annotations

from dataclasses import dataclass

from lonlib.util.validation import check_choice, check_field_types, check_range

ESTIMATES = ("nominal", "robust")


@dataclass(frozen=True)
class Scoring:
    """How a policy is scored: what Algorithm 2 compares and what the LON's nodes carry.

    The fitness is always Algorithm 1 under the environment's ``fitness_mode``; this says
    from which starts.
    """

    estimate: str = "nominal"
    """``nominal``: Algorithm 1 from the nominal start (the paper). ``robust``: the mean over
    ``starts`` perturbed starts (:func:`perturbed_offsets`), a fitness that a rounding in the
    start cannot flip."""
    starts: int = 8
    """``M``, the number of perturbed starts of the conditioning (and of ``robust``)."""
    noise: float = 0.01
    """Half-width of the uniform start perturbation, on x, x_dot, phi and phi_dot."""
    seed: int = 0
    """Seed of the perturbed starts' draw (the same starts for every policy)."""
    eval_seed: int = 0
    """Seed of the nominal start's draw (used only when ``initial_noise`` > 0)."""

    def __post_init__(self) -> None:
        check_field_types(self)
        check_choice("fitness_estimate", self.estimate, ESTIMATES)
        check_range("robust_starts", self.starts, 1, 100_000)
        check_range("robust_noise", self.noise, 0.0, 0.5)
        check_range("robust_seed", self.seed, 0, 2**63 - 1)
        check_range("eval_seed", self.eval_seed, 0, 2**63 - 1)
