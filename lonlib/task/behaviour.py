"""What an optimum does: a behaviour descriptor from its greedy rollout, and labels.

The paper names its optima by behaviour ("balancing" at 0.72 and above; carts that "come to
an immediate stop upon approaching the boundary" at 0.22); a LON node is otherwise only a
number. :func:`describe` replays a policy greedily once (the same start as the fitness
evaluation, so the rollout reproduces the optimum's fitness) and measures, per rod, the
upright share, the signed full turns and the mean angular speed while upright; the rods'
phase relation (the circular correlation ``mean cos(phi_i - phi_j)`` of neighbours: +1 in
phase, -1 anti-phase, ~0 independent); the carts' range and mean speed; the end reason and
step; and robustness: the fitness of the same policy from ``robustness_starts`` slightly
perturbed start states (all simulated as one batch).

:func:`label` turns a descriptor into one of :data:`LABELS` by documented thresholds
(:class:`BehaviourThresholds`), so labels can be recomputed with other thresholds from the
stored descriptors without simulating again. Experiments store the descriptor of every
local search (accepted or not) with its trial (columns ``b_*``) and the default label.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np

from lonlib.config import PendulumConfig, Scoring
from lonlib.task.pendulum import Policy
from lonlib.task.rollout import (
    Rollout,
    actor_policy,
    conditioning_batch,
    nominal_offsets,
    perturbed_offsets,
    run_policy,
)
from lonlib.util import portable_math
from lonlib.util.validation import check_field_types, check_range

LABELS = (
    "balancing",
    "one rod up",
    "spinning (in phase)",
    "spinning (anti-phase)",
    "spinning (independent)",
    "spinning",
    "swinging high",
    "swinging low",
    "stops at boundary",
    "crash",
)
"""Every label :func:`label` can return, from the most to the least accomplished."""

PREFIX = "b_"  # column prefix of descriptor fields in a trials table
ADDED_LATER = ("fitness_all", "fitness_mean", "robust_std")  # NaN when read from older tables


@dataclass(frozen=True)
class BehaviourDescriptor:
    """Measurements of one greedy rollout. Per-rod fields are tuples (one value per rod)."""

    fitness: float  # Algorithm 1 fitness of the nominal episode, config's fitness_mode
    fitness_all: float  # the same episode with "all rods upright" per step
    fitness_mean: float  # the same episode with the upright share per step
    upright_share: tuple[float, ...]  # share of executed steps with the rod upright
    turns: tuple[float, ...]  # signed full turns of the rod over the episode
    upright_speed: tuple[float, ...]  # mean |phi_dot| while upright [rad/s] (0 if never)
    phase: float  # mean cos(phi_i - phi_{i+1}) over steps and neighbours (nan for 1 rod)
    cart_range: float  # mean over carts of (max x - min x) [m]
    cart_speed: float  # mean |x_dot| over carts and steps [m/s]
    end_reason: str  # EndReason name
    end_step: int  # steps executed
    nominal_steps: int  # the episode's step limit
    robust_mean: float  # fitness from the M perturbed starts: mean
    robust_min: float  # worst
    robust_std: float  # and standard deviation (population, over the M starts)

    def to_columns(self) -> dict[str, float | int | str]:
        """Flat ``b_*`` columns for a trials table (per-rod fields as ``b_<name>_<rod>``)."""
        out: dict[str, float | int | str] = {}
        for name, value in asdict(self).items():
            if isinstance(value, tuple):
                out.update({f"{PREFIX}{name}_{i}": float(v) for i, v in enumerate(value)})
            else:
                out[f"{PREFIX}{name}"] = value
        return out

    @classmethod
    def from_columns(cls, row: dict) -> BehaviourDescriptor:
        """Inverse of :meth:`to_columns` (a trials-table row as a mapping)."""
        values = {}
        for f in fields(cls):
            if f.name in ("upright_share", "turns", "upright_speed"):
                rods = sorted(
                    (int(key.rsplit("_", 1)[1]), value)
                    for key, value in row.items()
                    if key.startswith(f"{PREFIX}{f.name}_") and key.rsplit("_", 1)[1].isdigit()
                )
                values[f.name] = tuple(float(value) for _, value in rods)
            elif f.name in ADDED_LATER:  # absent from tables stored before they existed
                values[f.name] = row.get(f"{PREFIX}{f.name}", float("nan"))
            else:
                values[f.name] = row[f"{PREFIX}{f.name}"]
        values["end_step"] = int(values["end_step"])
        values["nominal_steps"] = int(values["nominal_steps"])
        values["end_reason"] = str(values["end_reason"])
        return cls(**values)


@dataclass(frozen=True)
class BehaviourThresholds:
    """The rules of :func:`label`, applied in this order (README, "Behaviours"):

    1. ``balancing``: every rod upright for at least ``balance_share`` of the executed
       steps, slowly (mean ``|phi_dot|`` while upright below ``balance_speed``) and turning
       fewer than ``spin_turns`` times (a policy that balances and then crashes is still
       balancing: the paper names optima by what they achieve);
    2. ``crash``: the episode ended by collision or tether before ``early_end_share`` of
       the nominal steps; ``stops at boundary``: it ended at a track end that early;
       ``one rod up``: some rods balanced as in 1, not all.
    3. ``spinning``: some rod turns ``spin_turns`` full turns or more; with several rods the
       phase says ``in phase`` (>= ``phase_lock``), ``anti-phase`` (<= -``phase_lock``) or
       ``independent``.
    4. ``swinging high``: some rod upright for at least ``high_share`` of the steps;
       otherwise ``swinging low``.
    """

    early_end_share: float = 0.9
    balance_share: float = 0.5
    balance_speed: float = 0.5
    spin_turns: float = 2.0
    phase_lock: float = 0.5
    high_share: float = 0.01

    def __post_init__(self) -> None:
        check_field_types(self)
        for name in ("early_end_share", "balance_share", "phase_lock", "high_share"):
            check_range(name, getattr(self, name), 0.0, 1.0)
        check_range("balance_speed", self.balance_speed, 0.0, low_open=True)
        check_range("spin_turns", self.spin_turns, 0.0, low_open=True)


def describe(
    theta_or_policy: np.ndarray | Policy,
    config: PendulumConfig,
    scoring: Scoring = Scoring(),
) -> BehaviourDescriptor:
    """Descriptor of a greedy Actor (flat parameters) or any policy on ``config``.

    One batched call of the one rollout (:func:`lonlib.task.rollout.run_policy`): row 0 is the
    nominal episode, the one Algorithm 1 scores (so ``fitness`` is the optimum's stored
    fitness, bit for bit), traced step by step; rows 1..M start from the scoring's
    perturbed starts (the conditioning: ``robust_*``).
    """
    policy = as_policy(theta_or_policy, config)
    m = scoring.starts
    offsets = np.concatenate(
        [
            nominal_offsets(config, scoring.eval_seed),
            perturbed_offsets(config, m, scoring.noise, scoring.seed, scoring.eval_seed),
        ],
        axis=1,
    )
    result = run_policy(policy, config, offsets, trace=1)
    return describe_rollout(result, config, 0, result.fitness[1:])


def describe_actors(
    thetas: np.ndarray, config: PendulumConfig, scoring: Scoring = Scoring()
) -> list[BehaviourDescriptor]:
    """:func:`describe` of ``k`` flat Actors ``[k, P]`` as one batched rollout of
    ``k (1 + M)`` episodes (rows ``0..k-1`` nominal, then each Actor's ``M`` perturbed
    starts); descriptor ``b`` equals ``describe(thetas[b])`` bit for bit."""
    thetas = np.atleast_2d(np.asarray(thetas))
    k, m = thetas.shape[0], scoring.starts
    batch, offsets = conditioning_batch(thetas, config, scoring)
    result = run_policy(actor_policy(batch, config), config, offsets, trace=k)
    robust = result.fitness[k:].reshape(k, m)
    return [describe_rollout(result, config, b, robust[b]) for b in range(k)]


def describe_rollout(
    result: Rollout, config: PendulumConfig, row: int, robust: np.ndarray | None = None
) -> BehaviourDescriptor:
    """The descriptor of row ``row`` of a traced rollout, with the fitness from its
    perturbed starts ``robust [M]`` (summed left to right: defined bits); without them
    the ``robust_*`` fields are NaN (the label does not read them)."""
    end = int(result.end_step[row])
    trace = result.trace.row(row, end)
    n = config.n_carts
    phi, phi_dot, x, x_dot = trace.phi, trace.phi_dot, trace.x, trace.x_dot
    upright = trace.upright
    start_phi = np.mod(np.full(n, config.initial_angle), 2 * np.pi)
    unwrapped = np.unwrap(np.vstack([start_phi, phi]), axis=0)
    turns = (unwrapped[-1] - unwrapped[0]) / (2 * np.pi)
    speed_up = np.where(
        upright.any(axis=0),
        (np.abs(phi_dot) * upright).sum(axis=0) / np.maximum(upright.sum(axis=0), 1),
        0.0,
    )
    phase = float(np.mean(portable_math.cos(phi[:, :-1] - phi[:, 1:]))) if n > 1 else float("nan")
    robust = np.asarray([np.nan] if robust is None else robust, dtype=np.float64)
    robust_mean = float(np.add.accumulate(robust)[-1] / robust.size)
    robust_var = np.add.accumulate((robust - robust_mean) ** 2)[-1] / robust.size
    return BehaviourDescriptor(
        fitness=float(result.fitness[row]),
        fitness_all=float(result.fitness_all[row]),
        fitness_mean=float(result.fitness_mean[row]),
        upright_share=tuple(float(v) for v in upright.mean(axis=0)),
        turns=tuple(float(v) for v in turns),
        upright_speed=tuple(float(v) for v in speed_up),
        phase=phase,
        cart_range=float(np.mean(x.max(axis=0) - x.min(axis=0))),
        cart_speed=float(np.mean(np.abs(x_dot))),
        end_reason=result.end_reason_name(row),
        end_step=end,
        nominal_steps=config.steps,
        robust_mean=robust_mean,
        robust_min=float(robust.min()),
        robust_std=float(np.sqrt(robust_var)),
    )


def describe_columns(
    theta: np.ndarray, config: PendulumConfig, scoring: Scoring = Scoring()
) -> dict:
    """:func:`describe` as flat trials-table columns (``b_*``) plus the default ``label``:
    what experiments store with every trial."""
    descriptor = describe(theta, config, scoring)
    return {**descriptor.to_columns(), "label": label(descriptor)}


def descriptors_of(trials) -> list[BehaviourDescriptor | None]:
    """The stored descriptor of each row of a trials table (None where a trial has none)."""
    columns = [c for c in trials.columns if c.startswith(PREFIX)]
    rows = trials[columns].to_dict("records")
    # A trial without a descriptor has no end reason (NaN in a table where others have one).
    described = [isinstance(row.get(f"{PREFIX}end_reason"), str) for row in rows]
    return [
        BehaviourDescriptor.from_columns(row) if ok else None
        for row, ok in zip(rows, described, strict=True)
    ]


def relabel(trials, thresholds: BehaviourThresholds | None = None) -> list[str | None]:
    """Labels of a trials table's stored descriptors under other ``thresholds``."""
    return [None if d is None else label(d, thresholds) for d in descriptors_of(trials)]


def as_policy(theta_or_policy: np.ndarray | Policy, config: PendulumConfig) -> Policy:
    """A flat Actor vector becomes its greedy policy; a callable is returned as it is."""
    if callable(theta_or_policy):
        return theta_or_policy
    theta = np.asarray(theta_or_policy)
    if theta.ndim != 1:
        raise ValueError(f"theta must be one flat Actor vector, got shape {theta.shape}")
    return actor_policy(theta, config)


def label(descriptor: BehaviourDescriptor, thresholds: BehaviourThresholds | None = None) -> str:
    """The behaviour label of a descriptor (rules in :class:`BehaviourThresholds`)."""
    t = thresholds or BehaviourThresholds()
    share = np.array(descriptor.upright_share)
    turns = np.abs(np.array(descriptor.turns))
    slow = np.array(descriptor.upright_speed) < t.balance_speed
    balanced = (share >= t.balance_share) & slow & (turns < t.spin_turns)
    if balanced.all():
        return "balancing"
    early = descriptor.end_step < t.early_end_share * descriptor.nominal_steps
    if early and descriptor.end_reason in ("COLLISION", "TETHER"):
        return "crash"
    if early and descriptor.end_reason == "BOUNDARY":
        return "stops at boundary"
    if balanced.any():
        return "one rod up"
    if (turns >= t.spin_turns).any():
        if len(share) == 1 or np.isnan(descriptor.phase):
            return "spinning"
        if descriptor.phase >= t.phase_lock:
            return "spinning (in phase)"
        if descriptor.phase <= -t.phase_lock:
            return "spinning (anti-phase)"
        return "spinning (independent)"
    if (share >= t.high_share).any():
        return "swinging high"
    return "swinging low"
