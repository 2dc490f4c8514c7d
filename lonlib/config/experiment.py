"""Experiment configurations: which p values, how many runs, and every setting of a LON
sampling experiment; the named ``quick`` and ``paper`` configurations and YAML files."""

from __future__ import annotations

import dataclasses
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lonlib.config.ddpg import (
    EXECUTION_ONLY_DDPG_FIELDS,
    DDPGConfig,
    check_judging,
    without_default_judging,
)
from lonlib.config.pendulum import PendulumConfig
from lonlib.config.search import BasinHoppingConfig
from lonlib.config.task import GymnasiumTaskConfig
from lonlib.util.validation import (
    check_choice,
    check_field_types,
    check_keys,
    check_range,
    is_finite,
    read_yaml_mapping,
)

EXECUTORS = ("auto", "serial", "pool", "dask", "lockstep")  # lonlib.experiment.executors


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
    task: GymnasiumTaskConfig | None = None
    """A Gymnasium environment as the task instead of the coupled pendulums (``env`` then
    stays at its defaults and is not used); None: the coupled pendulums."""

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
        if self.task is not None:
            if not isinstance(self.task, GymnasiumTaskConfig):
                raise ValueError(f"task must be a GymnasiumTaskConfig, got {self.task!r}")
            if self.env != PendulumConfig():
                raise ValueError(
                    "env: the coupled pendulums' physics does not apply to a Gymnasium task; "
                    "remove env (or task)"
                )
            if self.executor == "lockstep" and self.task.search != "ddpg":
                raise ValueError(
                    f"executor: lockstep batches lonlib's DDPG (task.search: ddpg); task.search "
                    f"{self.task.search!r} runs with auto, serial, pool or dask"
                )

    @property
    def is_pendulums(self) -> bool:
        """Is the task the coupled pendulums (no ``task`` section)?"""
        return self.task is None

    def basin_hopping(self, p: float) -> BasinHoppingConfig:
        """Algorithm 2's settings for perturbation strength ``p``."""
        return BasinHoppingConfig(p, self.tolerance, self.max_local_searches)

    def to_dict(self) -> dict[str, Any]:
        """Plain mapping (YAML/JSON friendly) that :meth:`from_mapping` reads back."""
        out = dataclasses.asdict(self)
        out["perturbations"] = list(self.perturbations)
        if self.task is None:  # the pendulums' stored form (and digests) stay as they were
            out.pop("task")
        else:
            out["task"] = self.task.to_dict()
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
        task_values = values.pop("task", start.pop("task", None))
        task = None if task_values is None else GymnasiumTaskConfig.from_mapping(task_values)
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
        return cls(
            env=PendulumConfig.from_mapping(env), ddpg=DDPGConfig(**ddpg), task=task, **merged
        )

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
    return ExperimentConfig.from_mapping(read_yaml_mapping(path, "configuration"))
