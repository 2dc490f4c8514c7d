"""What good looks like: the reference controllers' scores (issue 48, "the docs hold their
numbers").

The table of ``docs/rollout.md`` ("What good looks like") scores the package's two reference
controllers (:mod:`lonlib.task.controllers`: the policy that never pushes and the
energy-pumping swing-up with an LQR balance law) on one and two carts under the default
physics, through the one rollout: from the noise-free start Algorithm 1 scores from, and
from one batch of :data:`NOISY_STARTS` starts with uniform noise of half-width
:data:`START_NOISE` on every state variable, drawn from seed :data:`NOISE_SEED`
(``lonlib.evaluate(policy, config, NOISY_STARTS, seed=NOISE_SEED)``).
``python -m lonlib.analysis.reference_controllers`` pastes the table into
``docs/rollout.md``; a test checks that the page holds what this module computes, and
``tests/project/test_docs_numbers.py`` checks the docs' other mentions of these scores
against :func:`nominal_score` and :func:`noisy_score`.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path

import numpy as np

from lonlib.analysis.holding import hold_measures
from lonlib.config import PendulumConfig
from lonlib.task.controllers import SwingUpBalanceController, zero_controller
from lonlib.task.pendulum import EndReason
from lonlib.task.rollout import evaluate, nominal_offsets, run_policy
from lonlib.util.readme_tables import splice

BEGIN = "<!-- reference-controllers:begin (python -m lonlib.analysis.reference_controllers) -->"
END = "<!-- reference-controllers:end -->"
PAGE = "docs/rollout.md"
START_NOISE = 0.02
"""Half-width of the start noise of the noisy rows (on x, x_dot, phi, phi_dot of every cart)."""
NOISY_STARTS = 32
"""Starts of the noisy rows, one batch drawn from :data:`NOISE_SEED`."""
NOISE_SEED = 0
CARTS = (1, 2)
CONTROLLERS = {"zero": zero_controller, "swing-up": SwingUpBalanceController}
"""The reference controllers by the name the rows use."""
ENDING = {
    EndReason.COLLISION: "collide",
    EndReason.TETHER: "break the tether",
    EndReason.BOUNDARY: "hit a track end",
}


@dataclass(frozen=True)
class NominalScore:
    """One controller's episode from the noise-free start."""

    fitness: float  # under "all rods upright" (the default fitness_mode)
    fitness_mean: float  # under the per-pendulum mean
    end_reason: str  # EndReason name
    end_step: int
    first_upright: int  # steps before the first with every rod upright (-1: none)
    upright_from: int  # the step from which every rod stays upright to the end (-1: never)


@dataclass(frozen=True)
class NoisyScore:
    """One controller's fitness over the noisy starts (``[NOISY_STARTS]`` arrays)."""

    fitness: np.ndarray
    end_reason: np.ndarray  # EndReason names
    end_step: np.ndarray

    @property
    def mean(self) -> float:
        return float(np.mean(self.fitness))

    @property
    def median(self) -> float:
        return float(np.median(self.fitness))

    @property
    def full_length(self) -> int:
        """Episodes that ran to the step limit."""
        return int(np.sum(self.end_reason == EndReason.STEP_LIMIT.name))

    def ended_by(self, reason: EndReason) -> int:
        return int(np.sum(self.end_reason == reason.name))


def physics(n_carts: int, integrator: str | None = None) -> PendulumConfig:
    """The default physics on ``n_carts`` carts (``integrator`` replaced when given)."""
    config = PendulumConfig(n_carts=n_carts)
    return replace(config, integrator=integrator) if integrator else config


@cache
def nominal_score(controller: str, n_carts: int, integrator: str | None = None) -> NominalScore:
    """``controller``'s episode from the noise-free start, traced: its fitness under both
    aggregations, how it ends, and when its rods come up (:func:`hold_measures`)."""
    config = physics(n_carts, integrator)
    rollout = run_policy(
        CONTROLLERS[controller](config), config, nominal_offsets(config), trace=True
    )
    _, first, _ = hold_measures(rollout, config)
    end = int(rollout.end_step[0])
    all_up = rollout.trace.upright.all(axis=2)[:end, 0]
    down = np.flatnonzero(~all_up)
    upright_from = -1 if not all_up[-1] else int(down[-1] + 1) if down.size else 0
    return NominalScore(
        fitness=float(rollout.fitness_all[0]),
        fitness_mean=float(rollout.fitness_mean[0]),
        end_reason=rollout.end_reason_name(0),
        end_step=end,
        first_upright=int(first[0]),
        upright_from=upright_from,
    )


@cache
def noisy_score(controller: str, n_carts: int, integrator: str | None = None) -> NoisyScore:
    """``controller`` from :data:`NOISY_STARTS` starts with U[-START_NOISE, START_NOISE]
    on every state variable, drawn from :data:`NOISE_SEED` (``lonlib.evaluate``)."""
    config = replace(physics(n_carts, integrator), initial_noise=START_NOISE)
    rollout = evaluate(CONTROLLERS[controller](config), config, NOISY_STARTS, seed=NOISE_SEED)
    return NoisyScore(
        fitness=rollout.fitness_all.copy(),
        end_reason=np.array([EndReason(int(r)).name for r in rollout.end_reason]),
        end_step=rollout.end_step.copy(),
    )


def _nominal_cell(score: NominalScore, swing_up: bool) -> str:
    text = f"{score.fitness:.4f}"
    if score.end_reason != EndReason.STEP_LIMIT.name:
        return f"{text} ({score.end_reason.lower()} at step {score.end_step})"
    if swing_up and score.upright_from >= 0:
        return (
            f"{text}: every rod up at step {score.first_upright}, "
            f"then for good from step {score.upright_from}"
        )
    return text


def _noisy_cell(score: NoisyScore) -> str:
    text = f"{score.mean:.3f} mean, median {score.median:.3f}"
    full, starts = score.full_length, len(score.fitness)
    if full == starts:
        return f"{text}; all {starts} run the {PendulumConfig().steps} steps"
    early = score.end_step[score.end_reason != EndReason.STEP_LIMIT.name]
    ends = ", ".join(
        f"{score.ended_by(reason)} {ENDING[reason]}" for reason in ENDING if score.ended_by(reason)
    )
    return (
        f"{text}; {full} of {starts} run the {PendulumConfig().steps} steps, {ends} "
        f"(at steps {early.min()}–{early.max()})"
    )


def reference_controllers_markdown() -> str:
    """The docs table: one row per controller and start, one column per number of carts."""
    noise = f"U[−{START_NOISE}, {START_NOISE}]"
    rows = [
        (
            "zero output (`a = 0.5`), noise-free start",
            [_nominal_cell(nominal_score("zero", n), False) for n in CARTS],
        ),
        (
            f"zero output, start noise {noise} on every state variable ({NOISY_STARTS} starts)",
            [_noisy_cell(noisy_score("zero", n)) for n in CARTS],
        ),
        (
            "energy-pumping swing-up + LQR balance, noise-free start",
            [_nominal_cell(nominal_score("swing-up", n), True) for n in CARTS],
        ),
        (
            f"the same, start noise {noise} ({NOISY_STARTS} starts)",
            [_noisy_cell(noisy_score("swing-up", n)) for n in CARTS],
        ),
        (
            "the same, noise-free, explicit Euler (`integrator: euler`)",
            [_nominal_cell(nominal_score("swing-up", n, "euler"), False) for n in CARTS],
        ),
        (
            f"zero output, start noise {noise}, explicit Euler",
            [_noisy_cell(noisy_score("zero", n, "euler")) for n in CARTS],
        ),
    ]
    lines = [
        "*Generated by `python -m lonlib.analysis.reference_controllers` (the default physics: "
        "the velocity motor, τ = 0.02 s, semi-implicit Euler unless the row says otherwise; "
        f"fitness: every rod upright; the noisy starts: one batch of {NOISY_STARTS} drawn "
        f"from seed {NOISE_SEED}, `lonlib.evaluate(policy, config, {NOISY_STARTS}, "
        f"seed={NOISE_SEED})`).*",
        "",
        "| controller | 1 cart | 2 carts |",
        "|---|---|---|",
    ]
    lines += [f"| {name} | {' | '.join(cells)} |" for name, cells in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Paste the table into ``docs/rollout.md`` of the project at the working directory
    (or at ``argv[0]``)."""
    root = Path(argv[0]) if argv else Path.cwd()
    page = root / PAGE
    page.write_text(splice(page.read_text(), BEGIN, END, reference_controllers_markdown()))
    return 0


__all__ = [
    "BEGIN",
    "CONTROLLERS",
    "END",
    "NOISE_SEED",
    "NOISY_STARTS",
    "NominalScore",
    "NoisyScore",
    "START_NOISE",
    "main",
    "noisy_score",
    "nominal_score",
    "physics",
    "reference_controllers_markdown",
]


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
