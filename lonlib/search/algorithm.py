"""Parameter-level basin hopping (paper Algorithm 2) with a pluggable local search.

Like :func:`scipy.optimize.basinhopping`, the global search only perturbs and accepts; the
local search is any callable ``F(theta, omega, seed) -> LocalOptimum`` (DDPG via
:func:`lonlib.ddpg.search_interface.ddpg_local_search`, a fast deterministic stand-in in the
tests), and like it the step and the acceptance are pluggable too (``take_step``,
``accept_test``; the defaults are the paper's: :func:`perturb_parameters`,
:func:`non_deteriorating`). Algorithm 2 as
written: start from random parameters, run ``F``; then repeatedly add U[-p, p] to **every**
Actor and Critic parameter of the incumbent, run ``F`` again and accept when ``f >= f*``
(equal fitness is accepted); the failure counter resets on acceptance and the run ends after
``tolerance`` consecutive failures, or after ``max_local_searches`` (so that a run always
ends). Every local search is recorded as a :class:`Trial`, accepted or not, with its parent.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from lonlib.config import BasinHoppingConfig
from lonlib.task.policy import NetSpec, actor_spec, critic_spec


@dataclass(frozen=True)
class LocalOptimum:
    """What a local search returns: fitness and the parameters reached, and what it knows
    of its start (NaN when a stand-in does not say)."""

    fitness: float
    theta: np.ndarray
    omega: np.ndarray
    env_steps: int = 0
    history: list[dict] | None = None  # per-episode training record, if the search keeps one
    start_fitness: float = float("nan")  # fitness of the (perturbed) start parameters
    stop_reason: str = ""  # why the local search stopped ("patience", "budget")
    behaviour: dict | None = None  # flat behaviour descriptor columns and label, if described

    @property
    def improved(self) -> bool:
        """Did the local search return something strictly fitter than its start?"""
        return bool(self.fitness > self.start_fitness)


LocalSearch = Callable[[np.ndarray, np.ndarray, int], LocalOptimum]
"""``F(theta, omega, seed)``: environment and hyperparameters are bound in the callable."""


@dataclass(frozen=True)
class Trial:
    """One local search of a run. ``parent`` is the index of the incumbent it was perturbed
    from (-1 for the first, which starts from random parameters)."""

    index: int
    parent: int
    fitness: float
    accepted: bool
    seconds: float
    env_steps: int
    start_fitness: float = float("nan")  # fitness of the perturbed start, before training
    improved: bool = False  # the local search returned something fitter than its start
    stop_reason: str = ""  # why the local search stopped
    behaviour: dict = dataclasses.field(default_factory=dict)  # lonlib.task.behaviour columns


@dataclass
class RunState:
    """Where a run stands; enough to resume it after its last finished local search."""

    trials: list[Trial]
    incumbent: LocalOptimum | None
    incumbent_index: int
    failures: int
    end_reason: str | None = None  # "tolerance" or "budget" once the run has ended

    @property
    def finished(self) -> bool:
        """True once the run has met its tolerance or its budget."""
        return self.end_reason is not None

    def record(
        self, trial: Trial, optimum: LocalOptimum | None, config: BasinHoppingConfig
    ) -> None:
        """Algorithm 2's bookkeeping after one local search: the incumbent moves on
        acceptance and the failure counter resets; T failures or the budget end the run.
        ``optimum`` may be None when replaying stored trials (the caller loads the final
        incumbent's parameters)."""
        self.trials.append(trial)
        if trial.accepted:
            self.incumbent, self.incumbent_index, self.failures = optimum, trial.index, 0
        else:
            self.failures += 1
        if self.failures >= config.tolerance:
            self.end_reason = "tolerance"
        elif len(self.trials) >= config.max_local_searches:
            self.end_reason = "budget"


def perturb(values: np.ndarray, strength: float, rng: np.random.Generator) -> np.ndarray:
    """Add U[-p, p] independently to every parameter (float32 in, float32 out)."""
    noise = rng.uniform(-strength, strength, size=values.shape)
    return (values.astype(np.float64) + noise).astype(np.float32)


TakeStep = Callable[
    [np.ndarray, np.ndarray, float, np.random.Generator], tuple[np.ndarray, np.ndarray]
]
"""``take_step(theta, omega, p, rng) -> (theta', omega')``: the start of the next local search
from the incumbent's parameters, drawing from the trial's perturbation stream ``rng``."""

AcceptTest = Callable[[float, float], bool]
"""``accept_test(f_new, f_best) -> bool``: does the new optimum replace the incumbent?"""


def perturb_parameters(
    theta: np.ndarray, omega: np.ndarray, strength: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 2's step: U[-p, p] on every Actor parameter, then on every Critic one."""
    return perturb(theta, strength, rng), perturb(omega, strength, rng)


def non_deteriorating(f_new: float, f_best: float) -> bool:
    """Algorithm 2's acceptance: ``f >= f*`` (equal fitness is accepted)."""
    return f_new >= f_best


@dataclass(frozen=True)
class TrialSeeds:
    """Independent random streams of one trial, spawned from ``(run seed, trial index)``:
    the perturbation's, and the local search's (DDPG's warm-up, noise, sampling and start
    noise). Greedy evaluations use the local search's own fixed stream (``eval_seed``) so
    that fitness is a function of the parameters alone."""

    perturbation: int
    local_search: int


def trial_seeds(run_seed: int, index: int) -> TrialSeeds:
    """The random streams of trial ``index`` of a run: a pure function of both."""
    perturbation, local = np.random.SeedSequence([run_seed, index]).spawn(2)
    return TrialSeeds(
        perturbation=int(perturbation.generate_state(1, np.uint64)[0]),
        local_search=int(local.generate_state(1, np.uint64)[0]),
    )


def random_parameters(run_seed: int, n_carts: int) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 2's random initial Actor and Critic of the run seeded ``run_seed``."""
    return random_networks(run_seed, actor_spec(n_carts), critic_spec(n_carts))


def random_networks(
    run_seed: int, actor: NetSpec, critic: NetSpec, critics: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 2's random initial Actor and Critic of the shapes given (any task's); with
    ``critics`` > 1 the Critic parameters are that many critics drawn one after the other and
    concatenated (the first is the one critic of ``critics`` = 1)."""
    rng = np.random.default_rng([run_seed, 1])
    theta = actor.initial(rng)
    return theta, np.concatenate([critic.initial(rng) for _ in range(critics)])


def search_start(
    run_seed: int,
    index: int,
    perturbation: float,
    incumbent: tuple[np.ndarray, np.ndarray] | None,
    initial: tuple[np.ndarray, np.ndarray] | None,
    take_step: TakeStep = perturb_parameters,
) -> tuple[np.ndarray, np.ndarray]:
    """The Actor and Critic that trial ``index`` of a run starts from: ``initial`` while the
    run has no ``incumbent`` (unused, and may be None, once it has), else ``take_step`` of
    the incumbent's parameters with the trial's perturbation stream (:func:`trial_seeds`).
    What a run asks for and what ``lonlib verify`` replays."""
    if incumbent is None:
        if initial is None:
            raise ValueError("the first search of a run needs the run's initial parameters")
        return initial
    rng = np.random.default_rng(trial_seeds(run_seed, index).perturbation)
    return take_step(incumbent[0], incumbent[1], perturbation, rng)


@dataclass(frozen=True)
class SearchRequest:
    """The next local search a run asks for: trial ``index`` from ``theta``/``omega``
    (perturbed from incumbent ``parent``, -1 for the random start) with DDPG seed ``seed``."""

    index: int
    parent: int
    theta: np.ndarray
    omega: np.ndarray
    seed: int


class BasinHoppingRun:
    """Algorithm 2 for one run, one local search at a time, with the local search run by
    the caller: :meth:`next_search` says what to search, :meth:`record` takes the optimum.

    The perturbation of trial ``i`` and the local search's seed are independent streams
    derived only from ``(run_seed, i)`` (:func:`trial_seeds`), so a run resumed from a stored
    ``state``, or driven by any executor, continues exactly as an uninterrupted one would.
    :meth:`steps` is the whole loop with a local search the run calls itself. ``take_step``
    and ``accept_test`` replace Algorithm 2's perturbation and acceptance (scipy's
    ``basinhopping`` has the same two hooks); their defaults are the paper's.
    """

    def __init__(
        self,
        initial: tuple[np.ndarray, np.ndarray],
        config: BasinHoppingConfig,
        run_seed: int,
        state: RunState | None = None,
        take_step: TakeStep = perturb_parameters,
        accept_test: AcceptTest = non_deteriorating,
    ) -> None:
        self.initial, self.config, self.run_seed = initial, config, run_seed
        self.take_step, self.accept_test = take_step, accept_test
        self.state = state or RunState(trials=[], incumbent=None, incumbent_index=-1, failures=0)

    @property
    def finished(self) -> bool:
        """True once the run has met its tolerance or its budget."""
        return self.state.finished

    def next_search(self) -> SearchRequest:
        """The next trial's start parameters and seed: the random start first, then the
        incumbent plus U[-p, p] on every Actor and Critic parameter."""
        if self.finished:
            raise RuntimeError("the run has ended; it asks for no more local searches")
        state = self.state
        index = len(state.trials)
        seeds = trial_seeds(self.run_seed, index)
        incumbent = state.incumbent
        theta, omega = search_start(
            self.run_seed,
            index,
            self.config.perturbation,
            None if incumbent is None else (incumbent.theta, incumbent.omega),
            self.initial,
            self.take_step,
        )
        parent = -1 if incumbent is None else state.incumbent_index
        return SearchRequest(index, parent, theta, omega, seeds.local_search)

    def record(self, request: SearchRequest, optimum: LocalOptimum, seconds: float) -> Trial:
        """Accept (``accept_test``, by default ``f >= f*``) or reject the optimum of ``request``
        and return its trial."""
        state = self.state
        if request.index != len(state.trials):
            raise ValueError(f"trial {request.index} recorded, trial {len(state.trials)} due")
        accepted = state.incumbent is None or bool(
            self.accept_test(optimum.fitness, state.incumbent.fitness)
        )
        trial = Trial(
            index=request.index,
            parent=request.parent,
            fitness=float(optimum.fitness),
            accepted=accepted,
            seconds=seconds,
            env_steps=optimum.env_steps,
            start_fitness=float(optimum.start_fitness),
            improved=optimum.improved,
            stop_reason=optimum.stop_reason,
            behaviour=dict(optimum.behaviour or {}),
        )
        state.record(trial, optimum, self.config)
        return trial

    def steps(self, local_search: LocalSearch) -> Iterator[tuple[RunState, Trial, LocalOptimum]]:
        """Algorithm 2's loop from where the run stands: one local search at a time (timed),
        yielding the state, the trial and the optimum after each so that the caller stores
        it before the next; ends with the run (T failures in a row, or the budget)."""
        while not self.finished:
            request = self.next_search()
            start = time.perf_counter()
            optimum = local_search(request.theta, request.omega, request.seed)
            trial = self.record(request, optimum, time.perf_counter() - start)
            yield self.state, trial, optimum


def basin_hopping_steps(
    local_search: LocalSearch,
    initial: tuple[np.ndarray, np.ndarray],
    config: BasinHoppingConfig,
    run_seed: int,
    state: RunState | None = None,
    take_step: TakeStep = perturb_parameters,
    accept_test: AcceptTest = non_deteriorating,
) -> Iterator[tuple[RunState, Trial, LocalOptimum]]:
    """Run Algorithm 2 one local search at a time, yielding after each.

    ``initial`` holds the random starting Actor and Critic; see :class:`BasinHoppingRun`.
    The caller stores each yielded trial before asking for the next.
    """
    run = BasinHoppingRun(initial, config, run_seed, state, take_step, accept_test)
    yield from run.steps(local_search)


def basin_hopping(
    local_search: LocalSearch,
    initial: tuple[np.ndarray, np.ndarray],
    config: BasinHoppingConfig,
    run_seed: int,
    take_step: TakeStep = perturb_parameters,
    accept_test: AcceptTest = non_deteriorating,
) -> RunState:
    """Run Algorithm 2 to its end and return the finished state (all trials, the best)."""
    steps = basin_hopping_steps(
        local_search, initial, config, run_seed, None, take_step, accept_test
    )
    *_, (state, _, _) = steps
    return state
