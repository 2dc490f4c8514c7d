"""The one rollout: every episode of a fixed policy that lonlib scores, describes or records.

Algorithm 1's fitness is chaotic in the last bits of a policy's arithmetic (most DDPG optima
are bang-bang policies whose crash step or number of turns flips on a rounding), so every
consumer runs the same loop: training's greedy evaluations and the start's score
(:mod:`lonlib.ddpg.trainer`), :func:`evaluate`, the behaviour descriptor and its perturbed starts
(:mod:`lonlib.task.behaviour`), recordings (:mod:`lonlib.analysis.recordings`), the calibration
study and
``lonlib verify``. No other module steps the simulator in a loop (a test checks it) except
DDPG's training episodes, which are not greedy rollouts.

The arithmetic is defined (see :func:`lonlib.task.policy.forward_numpy` and
:mod:`lonlib.util.portable_math`): float64 throughout, sums in a fixed order, ``exp``/``sin``/
``cos`` from IEEE basic operations. A row's result is therefore the same bits whatever the
batch size, the row's position in it, numpy's CPU dispatch or the CPU (tested).

Starts are given as offsets ``[4, B, n]`` (x, x_dot, phi, phi_dot of every cart) from the
noise-free start (carts at rest, evenly spaced, rods at ``initial_angle``):

* the **nominal** start (:func:`nominal_offsets`) is the one Algorithm 1 uses: zero, or the
  environment's ``initial_noise`` drawn once from ``eval_seed``, the same for every policy;
* the **perturbed** starts (:func:`perturbed_offsets`) add U[-noise, noise] to every
  coordinate, ``M`` draws from one fixed seed, the same for every policy: the conditioning
  of an optimum is its fitness over these starts (:class:`Scores`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from lonlib.config import PendulumConfig, Scoring
from lonlib.task import compiled
from lonlib.task.pendulum import CoupledPendulums, EndReason
from lonlib.task.policy import NetSpec, actor_spec, forward_numpy
from lonlib.util.validation import check_range

Policy = Callable[[np.ndarray], np.ndarray]


__all__ = [
    "Rollout",
    "Scores",
    "Trace",
    "evaluate",
    "nominal_offsets",
    "perturbed_offsets",
    "run_actors",
    "run_policy",
    "score_actors",
]


@dataclass(frozen=True)
class Trace:
    """Every step of a rollout, ``[T, B, ...]`` with ``T`` the longest episode; a row's
    entries after its end repeat its final state (use ``Rollout.end_step``)."""

    x: np.ndarray  # [T, B, n] cart centres after each step
    x_dot: np.ndarray  # [T, B, n]
    phi: np.ndarray  # [T, B, n] rod angles after each step, in [0, 2 pi)
    phi_dot: np.ndarray  # [T, B, n]
    sensors: np.ndarray  # [T, B, 10 n] what the policy saw before each step
    actions: np.ndarray  # [T, B, n] what it did
    upright: np.ndarray  # [T, B, n] bool, each rod upright after each step (the fitness's test)
    fitness: np.ndarray  # [T, B] running fitness (the config's ``fitness_mode``)

    def row(self, b: int, end_step: int) -> Trace:
        """Row ``b``'s steps ``[0, end_step)`` with the batch axis dropped (``[T_b, ...]``)."""
        return Trace(*(getattr(self, name)[:end_step, b] for name in _TRACE_FIELDS))


_TRACE_FIELDS = ("x", "x_dot", "phi", "phi_dot", "sensors", "actions", "upright", "fitness")


@dataclass(frozen=True)
class Rollout:
    """Algorithm 1's outcome for ``B`` episodes (``[B]`` arrays), under both aggregations."""

    fitness: np.ndarray  # under the config's fitness_mode
    fitness_all: np.ndarray  # steps with every rod upright / nominal steps (the paper's text)
    fitness_mean: np.ndarray  # mean upright share per step / nominal steps (its Algorithm 1)
    end_reason: np.ndarray  # EndReason per episode (int8)
    end_step: np.ndarray  # steps executed
    episode_return: np.ndarray  # the config's reward summed over the episode
    trace: Trace | None = None

    @property
    def steps(self) -> np.ndarray:
        """Steps executed (alias of ``end_step``)."""
        return self.end_step

    def end_reason_name(self, b: int = 0) -> str:
        """Row ``b``'s end reason as a name (``"STEP_LIMIT"``, ``"TETHER"``...)."""
        return EndReason(int(self.end_reason[b])).name


def nominal_offsets(config: PendulumConfig, eval_seed: int = 0) -> np.ndarray:
    """The start Algorithm 1 scores from, as offsets ``[4, 1, n]`` from the noise-free start:
    zero, or U[-initial_noise, initial_noise] drawn from ``eval_seed`` (what a simulator of
    one environment built with ``seed=eval_seed`` draws)."""
    shape = (4, 1, config.n_carts)
    if config.initial_noise <= 0:
        return np.zeros(shape)
    rng = np.random.default_rng(eval_seed)
    return rng.uniform(-config.initial_noise, config.initial_noise, size=shape)


def perturbed_offsets(
    config: PendulumConfig, starts: int, noise: float, seed: int = 0, eval_seed: int = 0
) -> np.ndarray:
    """``starts`` starts ``[4, starts, n]``: the nominal start plus U[-noise, noise] on every
    coordinate of every cart, drawn from ``seed`` (the same starts for every policy)."""
    check_range("robust_starts", starts, 1, 100_000)
    check_range("robust_noise", noise, 0.0, 0.5)
    draws = np.random.default_rng(seed).uniform(-noise, noise, size=(4, starts, config.n_carts))
    return nominal_offsets(config, eval_seed) + draws


def run_policy(
    policy: Policy, config: PendulumConfig, offsets: np.ndarray, trace: bool | int = False
) -> Rollout:
    """Run ``policy`` greedily from the starts ``offsets [4, B, n]`` until every episode has
    ended: the one loop that steps the simulator for a fixed policy.

    ``policy`` maps normalised sensors ``[B, 10 n]`` to actions ``[B, n]`` in [0, 1]; a batch
    of different policies is one callable that evaluates row ``b`` with policy ``b``. With
    ``trace`` every step of every row is kept (:class:`Trace`); an integer ``k`` keeps the
    first ``k`` rows only (about 1 MB per 2000-step row).
    """
    offsets = np.asarray(offsets, dtype=np.float64)
    if offsets.ndim != 3 or offsets.shape[0] != 4 or offsets.shape[2] != config.n_carts:
        raise ValueError(f"offsets must have shape [4, B, {config.n_carts}], got {offsets.shape}")
    sim = CoupledPendulums(config, offsets.shape[1])
    sim.reset(noise=offsets)
    kept_rows = sim.batch_size if trace is True else int(trace)
    if kept_rows < 0:
        raise ValueError(f"trace must be a bool or a number of rows >= 0, got {trace!r}")
    actors = len(np.atleast_2d(policy.thetas)) if isinstance(policy, ActorPolicy) else 1
    if actors not in (1, sim.batch_size):
        raise ValueError(f"{actors} Actors for {sim.batch_size} starts: give one or one per start")
    module = compiled.kernels() if isinstance(policy, ActorPolicy) else None
    if module is not None:
        return _run_compiled(module, policy, sim, min(kept_rows, sim.batch_size))
    episode_return = np.zeros(sim.batch_size)
    steps: list[tuple[np.ndarray, ...]] = []
    while not sim.done.all():
        observation = sim.observe()
        actions = np.asarray(policy(observation), dtype=np.float64)
        outcome = sim.step(actions)
        episode_return += outcome.reward
        if kept_rows:
            k = kept_rows
            steps.append(
                (
                    sim.x[:k].copy(),
                    sim.x_dot[:k].copy(),
                    sim.phi[:k].copy(),
                    sim.phi_dot[:k].copy(),
                    observation[:k],
                    actions[:k],
                    outcome.upright_each[:k],
                    sim.fitness[:k].copy(),
                )
            )
    kept = None
    if kept_rows:
        kept = Trace(*(np.stack(column) for column in zip(*steps, strict=True)))
    return Rollout(
        fitness=sim.fitness.copy(),
        fitness_all=sim.fitness_all.copy(),
        fitness_mean=sim.fitness_mean.copy(),
        end_reason=sim.end_reason.copy(),
        end_step=sim.step_count.copy(),
        episode_return=episode_return,
        trace=kept,
    )


def _run_compiled(module: Any, policy: ActorPolicy, sim: CoupledPendulums, kept: int) -> Rollout:
    """:func:`run_policy` of flat Actors on the compiled kernels (the same bits)."""
    batch = sim.batch_size
    thetas = np.ascontiguousarray(np.atleast_2d(policy.thetas), dtype=np.float64)
    if thetas.shape[0] not in (1, batch):
        raise ValueError(f"{thetas.shape[0]} Actors for {batch} starts: give one or one per start")
    which = np.arange(batch) if thetas.shape[0] == batch else np.zeros(batch, dtype=np.int64)
    fc, ic = compiled.pack(sim.config)
    compiled.apply_threads()
    sizes = np.array(policy.spec.sizes, dtype=np.int64)
    out = module.rollout_actors(fc, ic, sizes, thetas, which, sim._state_arrays(), kept)
    steps = sim.config.steps
    kept_trace = None
    if kept:
        kept_trace = Trace(
            *(out[name] for name in ("x", "x_dot", "phi", "phi_dot", "sensors", "actions")),
            upright=out["upright"],
            fitness=out["fitness"],
        )
    sums = out["sums"]
    return Rollout(
        fitness=sums[:, 0] / steps,
        fitness_all=sums[:, 1] / steps,
        fitness_mean=sums[:, 2] / steps,
        end_reason=out["end_reason"],
        end_step=out["end_step"],
        episode_return=out["episode_return"],
        trace=kept_trace,
    )


@dataclass(frozen=True, eq=False)
class ActorPolicy:
    """The greedy policy of flat Actors (:func:`actor_policy`): a callable on sensors, which
    :func:`run_policy` runs on the compiled kernels."""

    spec: NetSpec
    thetas: np.ndarray  # [P] shared by every row, or [B, P] one per row

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        return forward_numpy(self.spec, self.thetas, observation)


def actor_policy(thetas: np.ndarray, config: PendulumConfig) -> ActorPolicy:
    """The greedy policy of flat Actors ``[B, P]`` (row ``b`` acts with Actor ``b``) or of one
    Actor ``[P]`` shared by every row; validated (shape, finite) before any compute."""
    spec = actor_spec(config.n_carts)
    thetas = np.asarray(thetas)
    if thetas.ndim not in (1, 2) or thetas.shape[-1] != spec.n_params:
        raise ValueError(
            f"Actor parameters must have shape [{spec.n_params}] or [B, {spec.n_params}] for "
            f"{config.n_carts} cart(s), got {thetas.shape}"
        )
    if not np.isfinite(thetas).all():
        raise ValueError("Actor parameters contain NaN or infinite values")
    return ActorPolicy(spec, thetas)


def run_actors(
    thetas: np.ndarray,
    config: PendulumConfig,
    offsets: np.ndarray | None = None,
    eval_seed: int = 0,
    trace: bool | int = False,
) -> Rollout:
    """Greedy rollouts of flat Actors: ``thetas [B, P]`` one per row, from the nominal start
    (``offsets`` None: every row from :func:`nominal_offsets`) or from ``offsets [4, B, n]``;
    or one Actor ``[P]`` from each start in ``offsets``. ``trace`` as in :func:`run_policy`."""
    thetas = np.asarray(thetas)
    rows = thetas.shape[0] if thetas.ndim == 2 else 1
    policy = actor_policy(thetas, config)
    if offsets is None:
        offsets = np.repeat(nominal_offsets(config, eval_seed), rows, axis=1)
    return run_policy(policy, config, offsets, trace)


def evaluate(
    policy: Policy,
    config: PendulumConfig,
    batch_size: int = 1,
    seed: int | None = None,
    same_start: bool = False,
) -> Rollout:
    """Fitness (Algorithm 1) of a deterministic policy run in ``batch_size`` environments
    (through :func:`run_policy`).

    ``seed`` draws the initial-state noise when the config has ``initial_noise`` > 0; with
    ``same_start`` every environment starts from the state a batch of one would draw (the
    nominal start of ``eval_seed = seed``), otherwise each gets its own draw.
    """
    if not isinstance(batch_size, (int, np.integer)) or batch_size < 1:
        raise ValueError(f"batch_size must be an integer >= 1, got {batch_size!r}")
    n = config.n_carts
    if same_start or config.initial_noise <= 0:
        offsets = np.repeat(nominal_offsets(config, seed or 0), batch_size, axis=1)
    else:
        rng = np.random.default_rng(seed)
        offsets = rng.uniform(-config.initial_noise, config.initial_noise, (4, batch_size, n))
    return run_policy(policy, config, offsets)


@dataclass(frozen=True)
class Scores:
    """What :func:`score_actors` measured for ``B`` Actors (``[B]`` arrays)."""

    fitness: np.ndarray  # what Algorithm 2 compares (the scoring's estimate)
    nominal: Rollout  # the nominal episodes
    robust_mean: np.ndarray | None  # over the perturbed starts (None when not measured)
    robust_min: np.ndarray | None
    robust_std: np.ndarray | None

    @property
    def episode_return(self) -> np.ndarray:
        """The nominal episodes' reward sums (DDPG's plateau tie-breaker)."""
        return self.nominal.episode_return


def score_actors(
    thetas: np.ndarray,
    config: PendulumConfig,
    scoring: Scoring = Scoring(),
    conditioning: bool | None = None,
    trace: bool = False,
) -> Scores:
    """Score flat Actors ``[B, P]``: the nominal episode of each and, when ``conditioning``
    (default: when the estimate is ``robust``), its fitness from the ``M`` perturbed starts,
    all in one batched rollout of ``B (1 + M)`` episodes. With ``trace`` the nominal
    episodes keep every step (``Scores.nominal.trace``); the numbers do not change."""
    thetas = np.asarray(thetas)
    if thetas.ndim == 1:
        thetas = thetas[None]
    rows = thetas.shape[0]
    measure = scoring.estimate == "robust" if conditioning is None else conditioning
    nominal = nominal_offsets(config, scoring.eval_seed)
    if not measure:
        result = run_actors(thetas, config, np.repeat(nominal, rows, axis=1), trace=trace)
        return Scores(result.fitness, result, None, None, None)
    m = scoring.starts
    batch, offsets = conditioning_batch(thetas, config, scoring)
    result = run_actors(batch, config, offsets, trace=rows if trace else False)
    head = Rollout(*(getattr(result, name)[:rows] for name in _ROLLOUT_ARRAYS), result.trace)
    robust = result.fitness[rows:].reshape(rows, m)
    mean = _sequential_mean(robust)
    return Scores(
        fitness=mean if scoring.estimate == "robust" else head.fitness,
        nominal=head,
        robust_mean=mean,
        robust_min=robust.min(axis=1),
        robust_std=np.sqrt(_sequential_mean((robust - mean[:, None]) ** 2)),
    )


def conditioning_batch(
    thetas: np.ndarray, config: PendulumConfig, scoring: Scoring
) -> tuple[np.ndarray, np.ndarray]:
    """Actors ``[k (1 + M), P]`` and starts ``[4, k (1 + M), n]`` of one batched rollout:
    rows ``0..k-1`` each Actor from the nominal start, then Actor ``b``'s ``M`` perturbed
    starts at rows ``k + b M ... k + (b + 1) M - 1``."""
    k, m = thetas.shape[0], scoring.starts
    nominal = nominal_offsets(config, scoring.eval_seed)
    perturbed = perturbed_offsets(config, m, scoring.noise, scoring.seed, scoring.eval_seed)
    offsets = np.concatenate([np.repeat(nominal, k, axis=1), np.tile(perturbed, (1, k, 1))], axis=1)
    return np.concatenate([thetas, np.repeat(thetas, m, axis=0)]), offsets


def _sequential_mean(values: np.ndarray) -> np.ndarray:
    """Row means of ``[B, M]`` summed strictly left to right (defined bits, any CPU)."""
    return np.add.accumulate(values, axis=1)[:, -1] / values.shape[1]


_ROLLOUT_ARRAYS = (
    "fitness",
    "fitness_all",
    "fitness_mean",
    "end_reason",
    "end_step",
    "episode_return",
)
