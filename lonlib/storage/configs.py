"""Experiment configurations: which p values, how many runs, and every setting of a LON
sampling experiment; the named ``quick`` and ``paper`` configurations and YAML files."""

from __future__ import annotations

import dataclasses
import re
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from lonlib.search.algorithm import BasinHoppingConfig
from lonlib.task.pendulum import PendulumConfig
from lonlib.task.rollout import Scoring
from lonlib.util.validation import (
    check_choice,
    check_field_types,
    check_keys,
    check_range,
    is_finite,
)

EXECUTORS = ("auto", "serial", "pool", "dask", "lockstep")  # lonlib.experiment.executors
LEARNERS = ("lean", "autograd")  # DDPG's update: lonlib.ddpg.lean, lonlib.ddpg.reference
# torch's device types (a device is "type" or "type:index"), checked here without torch;
# lonlib.ddpg.trainer.check_device asks torch whether this machine computes on one
TORCH_DEVICE_TYPES = (
    "cpu",
    "cuda",
    "mps",
    "xpu",
    "meta",
    "hip",
    "ve",
    "fpga",
    "maia",
    "xla",
    "lazy",
    "vulkan",
    "ipu",
    "mkldnn",
    "opengl",
    "opencl",
    "ideep",
    "hpu",
    "mtia",
    "privateuseone",
)
TORCH_DEVICE = re.compile(rf"({'|'.join(TORCH_DEVICE_TYPES)})(:\d+)?")


@dataclass(frozen=True)
class DDPGConfig:
    """DDPG hyperparameters (the paper's ``h``). Paper values: buffer, batch, noise, lr,
    gamma. Ours: tau, the warm-up and the step budget (README, "DDPG local search").

    ``plateau_tiebreak``: when the greedy fitness ties the best so far, a higher greedy
    reward return counts as progress (it keeps the parameters and resets the patience), so
    a search on a zero-fitness plateau is judged by whether it is still getting closer.

    ``count_start``: the start parameters (and greedy evaluations during the warm-up, when
    the Actor is still the start) are candidates for the returned optimum. Off by default:
    a basin-hopping trial is then accepted only if learning produced the optimum.

    ``eval_seed``: the random stream of the greedy evaluations' start noise (used only when
    the environment's ``initial_noise`` > 0). It is the same for every policy and every
    trial, so an optimum's fitness is a function of its parameters alone.

    ``fitness_estimate``: what a greedy evaluation scores and so what the search keeps,
    returns and Algorithm 2 compares: ``nominal`` (Algorithm 1 from the fixed start, the
    paper) or ``robust`` (its mean over ``robust_starts`` starts perturbed by
    U[-``robust_noise``, ``robust_noise``], drawn from ``robust_seed``, the same for every
    policy; :class:`lonlib.task.rollout.Scoring`). Every trial records both, whichever is used.

    ``judge_every``: how often the search's policy is greedy-evaluated (judged: scored, a
    candidate for the returned optimum). 0 (default) judges it after every training episode;
    ``J`` > 0 judges it only after the episodes whose end crosses a multiple of ``J`` env
    steps of the search (above ``max_steps``: only the Actor at the stop is judged). The
    paper does not say when its local search evaluates; judging costs one greedy rollout
    (up to ``steps`` env steps) per judged policy, and training episodes end every 30-150
    env steps early on, so long searches set about ``steps``. The patience counts from the
    last judged improvement, so ``judge_every`` must be below ``patience_steps`` unless
    ``min_steps`` = ``max_steps`` (:func:`check_judging`).

    ``device`` and ``threads`` say where the computation runs, not what it computes.

    ``update``: ``"lean"`` (:class:`lonlib.ddpg.lean.LeanDDPG`, hand-written passes, the
    default) or ``"autograd"`` (:mod:`lonlib.ddpg.reference`, the reference); same algorithm.
    """

    buffer_size: int = 40_000
    """Replay buffer capacity, transitions (paper: 40 000)."""
    batch_size: int = 2000
    """Minibatch size, sampled every environment step (paper: 2000)."""
    noise_std: float = 0.1
    """Standard deviation of the Gaussian action noise (paper: 0.1)."""
    learning_rate: float = 1e-3
    """Adam's learning rate of Actor and Critic (paper: 0.001)."""
    gamma: float = 0.99
    """Discount factor (paper: 0.99)."""
    tau: float = 0.005
    """Soft target-update rate (ours: 0.005)."""
    warmup_steps: int = 2000
    """Environment steps with random actions before training starts."""
    max_steps: int = 150_000
    """Budget of one local search, environment steps."""
    min_steps: int = 60_000
    """A local search never stops for patience before this many steps."""
    patience_steps: int = 40_000
    """Stop when this many steps bring no new best greedy fitness."""
    eval_seed: int = 0
    """Random stream of the greedy evaluations' start noise (the same for every policy)."""
    fitness_estimate: str = "nominal"
    """What a greedy evaluation scores: ``nominal`` (Algorithm 1) or ``robust``."""
    robust_starts: int = 8
    """Perturbed starts of the ``robust`` estimate (and of the conditioning)."""
    robust_noise: float = 0.01
    """Half-width of the ``robust`` starts' uniform perturbation."""
    robust_seed: int = 0
    """Random stream of the ``robust`` starts."""
    plateau_tiebreak: bool = False
    """On equal greedy fitness, a higher greedy return counts as progress."""
    count_start: bool = False
    """The start parameters are candidates for the returned optimum."""
    judge_every: int = 0
    """Env steps between greedy evaluations (0: after every training episode)."""
    device: str = "cpu"
    """Where DDPG computes (``cpu``, ``cuda[:i]``); not what it computes."""
    threads: int = 1
    """torch CPU threads; not what it computes."""
    update: str = "lean"
    """The learner: ``lean`` (hand-written passes, default) or ``autograd`` (reference)."""

    @property
    def scoring(self) -> Scoring:
        """How greedy evaluations score a policy (:class:`lonlib.task.rollout.Scoring`)."""
        return Scoring(
            estimate=self.fitness_estimate,
            starts=self.robust_starts,
            noise=self.robust_noise,
            seed=self.robust_seed,
            eval_seed=self.eval_seed,
        )

    def __post_init__(self) -> None:
        check_field_types(self)
        for name in ("buffer_size", "batch_size", "warmup_steps", "max_steps", "patience_steps"):
            check_range(name, getattr(self, name), 1)
        check_range("min_steps", self.min_steps, 0)
        check_range("eval_seed", self.eval_seed, 0, 2**63 - 1)
        check_range("threads", self.threads, 1, 256)
        check_range("judge_every", self.judge_every, 0, 2**62)
        check_range("buffer_size", self.buffer_size, 1, 2**31 - 1)
        check_range("noise_std", self.noise_std, 0.0, 1.0)
        check_range("learning_rate", self.learning_rate, 0.0, 1.0, low_open=True)
        check_range("gamma", self.gamma, 0.0, 1.0)
        check_range("tau", self.tau, 0.0, 1.0, low_open=True)
        if self.warmup_steps > self.max_steps:
            raise ValueError(
                f"warmup_steps must be <= max_steps ({self.max_steps}) so that DDPG trains "
                f"at least once, got {self.warmup_steps!r}"
            )
        check_choice("update", self.update, LEARNERS)
        _ = self.scoring  # validates fitness_estimate and the robust_* fields by name
        if self.min_steps > self.max_steps:
            raise ValueError(
                f"min_steps must be <= max_steps ({self.max_steps}), got {self.min_steps!r}"
            )
        if not TORCH_DEVICE.fullmatch(self.device):
            raise ValueError(
                f"device {self.device!r} is not a torch device: expected a device type "
                f"({', '.join(TORCH_DEVICE_TYPES)}), optionally with ':index'"
            )


EXECUTION_ONLY_DDPG_FIELDS = ("device", "threads")  # where DDPG runs, not what it computes
NAMED_CONFIGS = ("quick", "reference", "paper", "one-cart")


@dataclass(frozen=True)
class ExperimentConfig:
    """One LON sampling experiment: which p values, how many runs, and every setting."""

    name: str = "quick"
    """Experiment name: letters, digits, '-' or '_' (the folder's default name)."""
    perturbations: tuple[float, ...] = (1e-3, 1e-4)
    """The perturbation strengths ``p`` sampled, each with ``runs`` runs."""
    runs: int = 4
    """Independent basin-hopping runs per ``p``."""
    tolerance: int = 2
    """Algorithm 2's ``T``: consecutive failures that end a run."""
    max_local_searches: int = 6
    """Local searches a run may take at most (so that every run ends)."""
    seed: int = 2024
    """Experiment seed: run ``(p, i)`` is seeded from ``(seed, p, i)``."""
    env: PendulumConfig = field(default_factory=PendulumConfig)
    """The task's physics and fitness (the paper's ``e``)."""
    ddpg: DDPGConfig = field(default_factory=DDPGConfig)
    """DDPG's hyperparameters (the paper's ``h``)."""
    note: str = ""
    """Free text stored with the experiment (e.g. why its budget is small)."""
    executor: str = "auto"
    """Where runs execute (:data:`lonlib.experiment.executors.EXECUTORS`); not what they compute."""
    slots: int = 16
    """Local searches trained as one batch by the lockstep executor; not results."""

    def __post_init__(self) -> None:
        check_field_types(self)
        if not self.name.replace("-", "").replace("_", "").isalnum():
            raise ValueError(f"name must be letters, digits, '-' or '_', got {self.name!r}")
        if isinstance(self.perturbations, list):
            object.__setattr__(self, "perturbations", tuple(self.perturbations))
        if not isinstance(self.perturbations, tuple) or not self.perturbations:
            raise ValueError(
                f"perturbations must list at least one p > 0, got {self.perturbations!r}"
            )
        for p in self.perturbations:
            if isinstance(p, bool) or not isinstance(p, (int, float)) or not is_finite(p):
                raise ValueError(f"perturbations must be numbers, got {p!r}")
            check_range("perturbations", p, 0.0, 10.0, low_open=True)
        if len(set(self.perturbations)) != len(self.perturbations):
            raise ValueError(f"perturbations must not repeat, got {self.perturbations}")
        check_range("runs", self.runs, 1, 1_000_000)
        check_choice("executor", self.executor, EXECUTORS)
        check_range("slots", self.slots, 1, 100_000)
        check_range("seed", self.seed, 0, 2**63 - 1)
        # BasinHoppingConfig validates tolerance and max_local_searches by name.
        self.basin_hopping(self.perturbations[0])
        if not isinstance(self.env, PendulumConfig):
            raise ValueError(f"env must be a PendulumConfig, got {self.env!r}")
        if not isinstance(self.ddpg, DDPGConfig):
            raise ValueError(f"ddpg must be a DDPGConfig, got {self.ddpg!r}")
        check_judging(self.ddpg)

    def basin_hopping(self, p: float) -> BasinHoppingConfig:
        """Algorithm 2's settings for perturbation strength ``p``."""
        return BasinHoppingConfig(p, self.tolerance, self.max_local_searches)

    def to_dict(self) -> dict[str, Any]:
        """Plain mapping (YAML/JSON friendly) that :meth:`from_mapping` reads back."""
        out = dataclasses.asdict(self)
        out["perturbations"] = list(self.perturbations)
        return out

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> ExperimentConfig:
        """Build from a mapping, e.g. YAML. ``base: quick|reference|paper`` starts from a named
        configuration; unknown keys are refused by name."""
        values = dict(_mapping("configuration", values))
        base = values.pop("base", None)
        if base is not None and base not in NAMED_CONFIGS:
            raise ValueError(f"base must be one of {NAMED_CONFIGS}, got {base!r}")
        start = named_config(base).to_dict() if base else cls().to_dict()
        check_keys("experiment", values, cls)
        given = sorted(set(values) - {"name"})
        env = {**start.pop("env"), **_mapping("env", values.pop("env", None))}
        ddpg = {**start.pop("ddpg"), **_mapping("ddpg", values.pop("ddpg", None))}
        merged = {**start, **values}
        if "note" not in values and given:
            merged["note"] = f"based on {base or 'the defaults'}, changed: {', '.join(given)}"
        if not isinstance(merged["perturbations"], (list, tuple)):
            raise ValueError(
                f"perturbations must be a list of numbers, got {merged['perturbations']!r}"
            )
        merged["perturbations"] = tuple(
            _as_float("perturbations", p) for p in merged["perturbations"]
        )
        check_keys("ddpg", ddpg, DDPGConfig)
        return cls(env=PendulumConfig.from_mapping(env), ddpg=DDPGConfig(**ddpg), **merged)

    def run_seed(self, p: float, run: int) -> int:
        """Seed of run ``(p, run)``: a pure function of (experiment seed, p, run index)."""
        p_key = zlib.crc32(repr(float(p)).encode())
        return int(np.random.SeedSequence([self.seed, p_key, run]).generate_state(1)[0])

    def comparable(self) -> dict[str, Any]:
        """Every setting that changes results: what must match to resume an experiment or
        add runs or p values to it. Where it runs (executor, slots, DDPG ``device`` and
        ``threads``; workers and scheduler are not configuration at all) and the note do
        not count: every executor gives a run the same trials."""
        out = self.to_dict()
        for key in ("runs", "perturbations", "note", "executor", "slots"):
            out.pop(key)
        for key in EXECUTION_ONLY_DDPG_FIELDS:
            out["ddpg"].pop(key)
        out["ddpg"] = without_default_judging(out["ddpg"])
        return out


def check_judging(hp: DDPGConfig) -> None:
    """ValueError, naming both fields, if ``hp.judge_every`` leaves the patience no room: the
    patience counts from the last judged improvement, so where it can stop a search
    (``min_steps`` < ``max_steps``) a policy must be judged more often than every
    ``patience_steps``. Checked where the stopping rule is final: by an experiment's
    configuration and by the trainer (a calibration study replaces the budget first)."""
    if hp.judge_every >= hp.patience_steps and hp.min_steps < hp.max_steps:
        raise ValueError(
            f"ddpg.judge_every must be < ddpg.patience_steps ({hp.patience_steps}) when "
            "patience can stop a search (min_steps < max_steps): the patience counts from the "
            f"last judged improvement, got {hp.judge_every!r}"
        )


def without_default_judging(ddpg: dict[str, Any]) -> dict[str, Any]:
    """DDPG settings (plain data) without ``judge_every`` where it is 0: results stored before
    the field existed judged every episode, which is what 0 means, so they stay comparable."""
    if ddpg.get("judge_every") == 0:
        ddpg.pop("judge_every")
    return ddpg


def _as_float(name: str, value: Any) -> float:
    if isinstance(value, bool):
        raise ValueError(f"{name} must be numbers, got {value!r}")
    try:
        return float(value)  # YAML 1.1 reads "1e-3" as a string
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be numbers, got {value!r}") from None


def _mapping(name: str, value: Any) -> dict:
    """``value`` as a mapping of settings (None, e.g. an empty YAML section, is empty)."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ValueError(f"{name} must be a mapping of settings, got {value!r}")
    return value


QUICK_DDPG = DDPGConfig(
    batch_size=256,
    buffer_size=20_000,
    warmup_steps=1000,
    max_steps=40_000,
    min_steps=20_000,
    patience_steps=15_000,
    plateau_tiebreak=True,
)


# Per p, of the committed data/reference: 2 x 10 runs, so that each p has at least 10 sinks
# and claims a and b can be computed (sampled with the one rollout, result-path version 2,
# on one core across sessions; docs/results.md has its measured cost). The first reference
# (2 x 6 runs, sampled before the one rollout) is in git history.
REFERENCE_RUNS = 10


# The paper's other problem (issue: "The top of the landscape"). Batch 256, not 2000: the
# calibration study measured one-cart balancing at batch 256 (2 of 2 seeds, first >= 0.9
# after 146k and 406k env steps), and a batch-2000 update costs ~2.2x more per env step,
# which would push 2 x 10 runs of searches this long past ~30 core-hours.
# Every search runs its full 400k env steps (min_steps = max_steps, so patience never stops
# it). A first attempt with min_steps 150k and patience 60k stopped all 11 of its searches at
# ~150k on spinning plateaus (best 0.744, none balancing): the searches that continue from a
# perturbed optimum score their best at their first greedy evaluation and fall to a median
# greedy fitness of ~0.05-0.5 while the fresh replay buffer refills, and the calibration seed
# that balanced at 406k had plateaued since ~38k, so no patience short of the budget lets
# balancing appear. The local search keeps its best Actor, so running on never lowers it.
# A search's policy is judged every 2000 env steps (judge_every), not after every training
# episode: early episodes end every 30-150 env steps and each judgement is a greedy rollout
# of up to 2000 steps, which made greedy rollouts 96 % of a two-cart study's time and held
# a first one-cart attempt to ~14 env steps/s per search (docs/study-two-cart.md).
# Runs end after ONE_CART_MAX_LOCAL_SEARCHES searches. T = 5 alone does not end them on one
# cart: the top is a plateau (measured after 60 searches at p = 1e-3: 32 of 57 accepted
# optima score exactly 0.9765, upright from step 47), Algorithm 2 accepts equal fitness and
# resets its failure counter, so every run walked the plateau towards the 100-search budget
# (~800M env steps, ~100 h on two cores). 10 is close to the committed two-cart reference's
# run lengths (its 20 runs ended by T = 5 after 7-15 searches, mean 10.1, median 9.5): 2 x
# 10 runs x 10 searches, 80M env steps.
ONE_CART_RUNS = 10
ONE_CART_MAX_LOCAL_SEARCHES = 10
ONE_CART_DDPG = DDPGConfig(
    batch_size=256,
    max_steps=400_000,
    min_steps=400_000,
    patience_steps=60_000,
    judge_every=2000,
)


def named_config(name: str) -> ExperimentConfig:
    """The built-in configurations (:data:`NAMED_CONFIGS`): ``one-cart`` (the paper's one
    pendulum problem, committed under ``data/one-cart``), ``quick`` (minutes on a laptop:
    the calibrated physics with a shrunk DDPG budget, not the paper's experiment),
    ``reference`` (the experiment whose results are committed under ``data/reference``:
    both p, T = 5, the paper's DDPG, fewer runs than the paper) and ``paper`` (the paper's
    scale). All three share the physics (``PendulumConfig()``): one model, three budgets."""
    if name == "quick":
        return ExperimentConfig(
            name="quick",
            perturbations=(1e-3, 1e-4),
            runs=4,
            tolerance=2,
            max_local_searches=5,
            ddpg=QUICK_DDPG,
            executor="lockstep",
            slots=8,
            note="quick: DDPG budget shrunk (batch 256, <= 40 000 env steps per local search, "
            "T = 2, 4 runs per p); its LON illustrates the method, it is not the paper's "
            "experiment",
        )
    if name == "reference":
        return ExperimentConfig(
            name="reference",
            perturbations=(1e-3, 1e-4),
            runs=REFERENCE_RUNS,
            tolerance=5,
            max_local_searches=100,
            ddpg=DDPGConfig(),
            executor="lockstep",
            slots=REFERENCE_RUNS,
            note=f"reference: 2 x {REFERENCE_RUNS} runs, T = 5, the paper's DDPG and budget; "
            "the paper's algorithm with fewer runs than its 2 x 100",
        )
    if name == "one-cart":
        return ExperimentConfig(
            name="one-cart",
            perturbations=(1e-3, 1e-4),
            runs=ONE_CART_RUNS,
            tolerance=5,
            max_local_searches=ONE_CART_MAX_LOCAL_SEARCHES,
            env=PendulumConfig(n_carts=1),
            ddpg=ONE_CART_DDPG,
            executor="lockstep",
            slots=ONE_CART_RUNS,
            note=f"one-cart: the paper's other problem, 2 x {ONE_CART_RUNS} runs, T = 5 and at "
            f"most {ONE_CART_MAX_LOCAL_SEARCHES} local searches per run (the plateau at the "
            "top keeps T = 5 from ending runs), the paper's DDPG at batch 256 with searches "
            "of 400k env steps each (one-cart balancing came after 146k-406k), judged every "
            "2000 env steps; the nominal fitness",
        )
    if name == "paper":
        return ExperimentConfig(
            name="paper",
            perturbations=(1e-3, 1e-4),
            runs=100,
            tolerance=5,
            max_local_searches=100,
            ddpg=DDPGConfig(),
            note="paper scale: 2 x 100 runs, T = 5, 2000 steps, paper DDPG hyperparameters",
        )
    raise ValueError(f"unknown configuration {name!r}; use one of {NAMED_CONFIGS} or a YAML file")


def load_config(spec: str | Path) -> ExperimentConfig:
    """A named configuration or a YAML file path."""
    path = Path(spec)
    if str(spec) in NAMED_CONFIGS:
        return named_config(str(spec))
    if not path.exists():
        raise ValueError(f"configuration {spec!r} is neither one of {NAMED_CONFIGS} nor a file")
    if not path.is_file():
        raise ValueError(f"{path}: is a folder, not a configuration file")
    try:
        values = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as error:
        raise ValueError(f"{path}: not valid YAML ({error})") from None
    if not isinstance(values, dict):
        raise ValueError(f"{path}: expected a mapping of configuration keys")
    values.setdefault("name", path.stem)
    return ExperimentConfig.from_mapping(values)
