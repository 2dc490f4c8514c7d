"""The hold test (issue 46): does DDPG keep the top of the landscape once it is there?

From a start at the top, perturbed as basin hopping perturbs (U[-p, p] on every parameter of
Actor and Critic, :func:`lonlib.search.perturb_parameters`), the reference experiment's DDPG
local search (:class:`lonlib.ddpg.trainer.SlotTrainer`, the reference's
:class:`lonlib.config.ddpg.DDPGConfig`: batch 2000, at most 150k env steps) runs with
``seeds`` seeds per p in three **arms**:

* ``fresh``: the two-cart imitation Actor (:mod:`lonlib.calibration.imitation`) with a fresh
  random Critic, as Algorithm 2's first step;
* ``fitted``: the same Actor with a Critic first fitted with the Actor frozen
  (``critic_fit_steps`` env steps of the same DDPG, every Actor update undone after each step,
  from the fresh Critic of seed 0; one fit shared by the arm's searches), then both perturbed,
  as a chain's later steps inherit a trained Critic;
* ``control``: a one-cart balancing optimum of ``data/one-cart/`` with its stored Critic
  (``control_critic: stored``; ``fresh`` draws one) under the same protocol on one cart.

Searches ``(fresh, p, i)`` and ``(fitted, p, i)`` share the perturbation of the Actor and the
DDPG seed (common random numbers); the control draws from the same streams.

A search returns its best-so-far, which starts near the top, so that number says nothing.
Every judged policy is recorded (env step, fitness under both aggregations, behaviour label,
:class:`lonlib.calibration.judged_log.JudgedLog`), and per search the record keeps the **last
judged fitness**, the share of judged policies >= ``hold_fitness`` after the first
``late_steps`` env steps, and the label of the last judged policy.

**Pre-registered** (``docs/study-geometry.md``, "The hold test"): an arm *holds* at a p when
the last judged fitness is >= ``hold_fitness`` (0.9) in >= ``hold_seeds`` (3) of its
``seeds`` (4) seeds (:func:`held`).

Storage (``OUT``): ``settings.json`` (the configuration; a folder of other settings is
refused), ``fitted_critic.npz`` (the fitted Critic), ``searches/<name>.json`` and ``.npz``
(each search written atomically as soon as it finishes: parameters first, the JSON is the
commit point), ``inflight/`` (checkpoints of the search in progress, every
``checkpoint_seconds``), ``searches.csv``, ``summary.csv`` and ``summary.md``. Running again
resumes: finished searches are never redone, a search in flight continues from its checkpoint.
"""

from __future__ import annotations

import dataclasses
import io
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from lonlib.calibration.imitation import DEFAULT_TEACHER
from lonlib.calibration.inflight import CellCheckpoint
from lonlib.calibration.judged_log import JudgedLog
from lonlib.config import DDPGConfig, PendulumConfig, named_config
from lonlib.ddpg.slots import LocalSearchResult
from lonlib.ddpg.trainer import SlotTrainer
from lonlib.search.algorithm import perturb_parameters
from lonlib.storage.atomic import atomic_write, read_json, write_json
from lonlib.storage.digests import reseal_files_if_sealed
from lonlib.task.behaviour import LABELS
from lonlib.task.policy import actor_spec, critic_spec
from lonlib.util.validation import check_choice, check_field_types, check_keys, check_range

ARMS = ("fresh", "fitted", "control")
CRITICS = ("stored", "fresh")
DEFAULT_ACTOR = "data/studies/hold-test/actor.npy"
PROGRESS_SECONDS = 60.0
SUMMARY_COLUMNS = (
    "arm",
    "p",
    "seeds_done",
    "held_seeds",
    "held",
    "last_judged",
    "late_share_mean",
    "returned_mean",
    "labels_at_end",
)


def _reference_ddpg() -> DDPGConfig:
    return named_config("reference").ddpg


@dataclass(frozen=True)
class HoldTestConfig:
    """Every setting of the hold test (stored in ``settings.json``)."""

    actor: str = DEFAULT_ACTOR
    """The two-cart Actor at the top (``.npy``, float32, Eq. 1 order)."""
    control: str = DEFAULT_TEACHER
    """The control arm's one-cart optimum (``.npz`` with ``theta`` and ``omega``)."""
    control_critic: str = "stored"
    """The control's Critic: the optimum's ``stored`` one or a ``fresh`` random one."""
    perturbations: tuple[float, ...] = (1e-4, 1e-3)
    seeds: int = 4
    arms: tuple[str, ...] = ARMS
    seed: int = 0
    """Seeds the perturbations, the DDPG streams and the fresh Critics."""
    critic_fit_steps: int = 20_000
    """Env steps of the ``fitted`` arm's Critic fit (the Actor frozen)."""
    late_steps: int = 20_000
    """The late share counts the judged policies after this many env steps of a search."""
    hold_fitness: float = 0.9
    hold_seeds: int = 3
    ddpg: DDPGConfig = field(default_factory=_reference_ddpg)
    """The reference experiment's DDPG (batch 2000, <= 150k env steps, judged after every
    training episode)."""

    def __post_init__(self) -> None:
        check_field_types(self)
        check_choice("control_critic", self.control_critic, CRITICS)
        if not self.perturbations:
            raise ValueError("perturbations must list at least one p")
        for p in self.perturbations:
            check_range("perturbations", p, 0.0, 1.0, low_open=True)
        if len(set(self.perturbations)) != len(self.perturbations):
            raise ValueError(f"perturbations must be distinct, got {self.perturbations}")
        if not self.arms or len(set(self.arms)) != len(self.arms):
            raise ValueError(f"arms must be distinct names among {ARMS}, got {self.arms}")
        for arm in self.arms:
            check_choice("arms", arm, ARMS)
        check_range("seeds", self.seeds, 1, 10_000)
        check_range("seed", self.seed, 0, 2**63 - 1)
        check_range("critic_fit_steps", self.critic_fit_steps, 1, 10**9)
        check_range("late_steps", self.late_steps, 0)
        check_range("hold_fitness", self.hold_fitness, 0.0, 1.0)
        check_range("hold_seeds", self.hold_seeds, 1, self.seeds)

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-able): what ``settings.json`` holds."""
        values = dataclasses.asdict(self)
        values["perturbations"] = list(self.perturbations)
        values["arms"] = list(self.arms)
        return values

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> HoldTestConfig:
        """From YAML or ``settings.json``; ``ddpg`` overrides the reference's DDPG field by
        field. Unknown keys are refused by name."""
        values = dict(values)
        check_keys("hold test", values, cls)
        ddpg = values.pop("ddpg", None) or {}
        check_keys("ddpg", ddpg, DDPGConfig)
        for name in ("perturbations", "arms"):
            if name in values:
                values[name] = tuple(values[name])
        return cls(**values, ddpg=dataclasses.replace(_reference_ddpg(), **ddpg))

    def with_overrides(
        self, seeds: int | None = None, max_steps: int | None = None, batch: int | None = None
    ) -> HoldTestConfig:
        """The command line's overrides (None keeps a value); a smaller ``max_steps`` also
        lowers ``min_steps`` and the warm-up to fit."""
        config = self
        if seeds is not None:
            config = dataclasses.replace(
                config, seeds=seeds, hold_seeds=min(self.hold_seeds, seeds)
            )
        hp = config.ddpg
        if max_steps is not None:
            hp = dataclasses.replace(
                hp,
                max_steps=max_steps,
                min_steps=min(hp.min_steps, max_steps),
                warmup_steps=min(hp.warmup_steps, max_steps),
            )
        if batch is not None:
            hp = dataclasses.replace(hp, batch_size=batch)
        return dataclasses.replace(config, ddpg=hp)


def load_hold_config(spec: str | Path | None) -> HoldTestConfig:
    """The default configuration (None) or a YAML file's."""
    if spec is None:
        return HoldTestConfig()
    from lonlib.util.validation import read_yaml_mapping

    values = read_yaml_mapping(Path(spec), "hold test")
    values.pop("name")  # the file's stem: a hold test is named by its folder
    return HoldTestConfig.from_mapping(values)


@dataclass(frozen=True)
class SearchSpec:
    """One search of the hold test."""

    arm: str
    p: float
    seed_index: int

    @property
    def name(self) -> str:
        return f"{self.arm}_p={self.p:g}_seed={self.seed_index}"


def plan(config: HoldTestConfig) -> list[SearchSpec]:
    """Every search, seed by seed (so a drained test has every arm and p at equal depth)."""
    return [
        SearchSpec(arm, p, i)
        for i in range(config.seeds)
        for p in config.perturbations
        for arm in config.arms
    ]


def search_seeds(config: HoldTestConfig, spec: SearchSpec) -> tuple[np.random.Generator, int]:
    """The perturbation stream and the DDPG seed of a search: a function of (seed, p's place,
    seed index), the same in every arm."""
    p_index = config.perturbations.index(spec.p)
    perturbation, local = np.random.SeedSequence([config.seed, p_index, spec.seed_index]).spawn(2)
    return np.random.default_rng(perturbation), int(local.generate_state(1, np.uint64)[0])


def fresh_critic(config: HoldTestConfig, n_carts: int, seed_index: int) -> np.ndarray:
    """A random Critic (PyTorch's default initialisation) of seed ``seed_index``."""
    return critic_spec(n_carts).initial(np.random.default_rng([config.seed, 3, seed_index]))


def load_actor(path: str | Path) -> np.ndarray:
    """The two-cart Actor at the top (``.npy``)."""
    theta = np.load(Path(path))
    if theta.shape != (actor_spec(2).n_params,) or not np.isfinite(theta).all():
        raise ValueError(f"{path}: not a finite two-cart Actor (shape {theta.shape})")
    return theta.astype(np.float32)


def load_control(config: HoldTestConfig, seed_index: int) -> tuple[np.ndarray, np.ndarray]:
    """The control's one-cart Actor and Critic (stored or fresh)."""
    with np.load(Path(config.control)) as data:
        theta, omega = np.asarray(data["theta"], np.float32), np.asarray(data["omega"], np.float32)
    if theta.shape != (actor_spec(1).n_params,) or omega.shape != (critic_spec(1).n_params,):
        raise ValueError(f"{config.control}: not a one-cart optimum ({theta.shape}, {omega.shape})")
    if config.control_critic == "fresh":
        omega = fresh_critic(config, 1, seed_index)
    return theta, omega


def fit_critic(
    theta: np.ndarray, omega: np.ndarray, env: PendulumConfig, hp: DDPGConfig, steps: int, seed: int
) -> tuple[np.ndarray, bool]:
    """Fit a Critic to the frozen Actor ``theta``: DDPG (``hp``: buffer, batch, noise, learning
    rate, gamma, tau, warm-up) for ``steps`` env steps, every Actor update undone after each
    step (acting and the Critic's targets use ``theta`` throughout; the Critic's update comes
    before the Actor's in a step). Returns the Critic and whether the learner's Actor is
    ``theta`` again at the end (a check that it stayed frozen)."""
    fit = dataclasses.replace(
        hp,
        max_steps=steps,
        min_steps=steps,
        patience_steps=steps,
        warmup_steps=min(hp.warmup_steps, steps),
        judge_every=steps + 1,  # only the Actor at the stop is judged
    )
    trainer = SlotTrainer(theta[None], omega[None], [seed], env, fit)
    frozen = trainer.learner.actor_params.clone()
    result: LocalSearchResult | None = None
    while trainer.busy.any():
        for _, finished in trainer.step():
            result = finished
        trainer.learner.actor_params.copy_(frozen)
    assert result is not None
    unchanged = bool(np.array_equal(trainer.learner.actor_flat()[0], theta))
    return result.omega.astype(np.float32), unchanged


def held(last: list[float], config: HoldTestConfig) -> bool | None:
    """The pre-registered verdict from the last judged fitness of an arm's finished searches
    at one p: True when >= ``hold_seeds`` reach ``hold_fitness``, False when too few can,
    None while the searches still to run could tip it."""
    reached = sum(value >= config.hold_fitness for value in last)
    if reached >= config.hold_seeds:
        return True
    if reached + (config.seeds - len(last)) < config.hold_seeds:
        return False
    return None


def judged_measures(
    steps: list[int], fitness: list[float], labels: list[str], config: HoldTestConfig
) -> dict[str, Any]:
    """A search's measures from its judged policies in order: the last judged fitness, env
    step and label, the late share (judged after ``late_steps`` env steps scoring >=
    ``hold_fitness``; None if none was judged that late) and the counts."""
    late = [f for s, f in zip(steps, fitness, strict=True) if s > config.late_steps]
    return {
        "judged": len(fitness),
        "last_judged_fitness": fitness[-1] if fitness else None,
        "last_judged_steps": steps[-1] if steps else None,
        "last_judged_label": labels[-1] if labels else None,
        "late_judged": len(late),
        "late_share": (sum(f >= config.hold_fitness for f in late) / len(late)) if late else None,
        "max_judged_fitness": max(fitness) if fitness else None,
        "min_judged_fitness": min(fitness) if fitness else None,
    }


class HoldTest:
    """The hold test in folder ``out`` (module docstring)."""

    def __init__(self, config: HoldTestConfig, out: str | Path) -> None:
        self.config, self.out = config, Path(out)
        self.searches = self.out / "searches"

    # ------------------------------------------------------------------ settings
    def check_settings(self) -> None:
        """Refuse a folder made with other settings (naming its file); write them if new."""
        path = self.out / "settings.json"
        settings = self.config.to_dict()
        if path.exists():
            stored = read_json(path)
            if stored != json.loads(json.dumps(settings)):
                raise ValueError(
                    f"{path}: this folder's hold test has other settings; use another folder "
                    "or the stored settings"
                )
            return
        self.out.mkdir(parents=True, exist_ok=True)
        write_json(path, settings)

    def paths(self, spec: SearchSpec) -> tuple[Path, Path]:
        return self.searches / f"{spec.name}.json", self.searches / f"{spec.name}.npz"

    def finished(self, spec: SearchSpec) -> dict[str, Any] | None:
        path = self.paths(spec)[0]
        return read_json(path) if path.exists() else None

    # ------------------------------------------------------------------ starts
    def fitted_critic(self, progress: bool = False) -> np.ndarray:
        """The ``fitted`` arm's Critic: read from ``fitted_critic.npz`` or fitted and stored."""
        path = self.out / "fitted_critic.npz"
        if path.exists():
            with np.load(path) as data:
                return data["omega"]
        c = self.config
        clock = time.perf_counter()
        omega, unchanged = fit_critic(
            load_actor(c.actor),
            fresh_critic(c, 2, 0),
            PendulumConfig(),
            c.ddpg,
            c.critic_fit_steps,
            search_seeds(c, SearchSpec("fitted", c.perturbations[0], 0))[1] ^ 1,
        )
        buffer = io.BytesIO()
        np.savez(buffer, omega=omega, actor_unchanged=np.bool_(unchanged))
        atomic_write(path, buffer.getvalue())
        if progress:
            print(
                f"{time.strftime('%H:%M:%S')} critic fitted ({c.critic_fit_steps} env steps, "
                f"{time.perf_counter() - clock:.0f} s, Actor unchanged: {unchanged})",
                file=sys.stderr,
                flush=True,
            )
        return omega

    def start(self, spec: SearchSpec, progress: bool = False):
        """Env, perturbed start Actor and Critic, and DDPG seed of a search."""
        c = self.config
        rng, ddpg_seed = search_seeds(c, spec)
        if spec.arm == "control":
            env = PendulumConfig(n_carts=1)
            theta, omega = load_control(c, spec.seed_index)
        else:
            env = PendulumConfig()
            theta = load_actor(c.actor)
            omega = (
                self.fitted_critic(progress)
                if spec.arm == "fitted"
                else fresh_critic(c, 2, spec.seed_index)
            )
        theta, omega = perturb_parameters(theta, omega, spec.p, rng)
        return env, theta, omega, ddpg_seed

    # ------------------------------------------------------------------ one search
    def run_search(
        self, spec: SearchSpec, checkpoint_seconds: float = 600.0, progress: bool = False
    ) -> dict[str, Any]:
        """Run (or continue) one search and store it atomically; returns its record."""
        c = self.config
        env, theta, omega, ddpg_seed = self.start(spec, progress)
        settings = {"search": spec.name, "hold_test": c.to_dict()}
        checkpoint = CellCheckpoint(self.out, spec.name)
        log = JudgedLog(env, 1)
        restored = checkpoint.load(settings)
        if restored is None:
            trainer = SlotTrainer(theta[None], omega[None], [ddpg_seed], env, c.ddpg)
            seconds_before = 0.0
        else:
            trainer, state = restored
            log.restore(state["judged"])
            seconds_before = float(state["seconds"])
        trainer.on_judged = log
        clock = time.perf_counter()
        saved = shown = time.monotonic()
        steps_at_start = int(trainer.steps.max())
        result: LocalSearchResult | None = None
        last_theta: dict[str, np.ndarray] = {}

        def keep_last(judged, nominal) -> None:
            log(judged, nominal)
            last_theta["theta"] = judged[-1][2]

        trainer.on_judged = keep_last
        while result is None:
            for _, finished in trainer.step():
                result = finished
            if result is not None or int(trainer.steps[0]) % 1000:
                continue
            now = time.monotonic()
            seconds = seconds_before + time.perf_counter() - clock
            if checkpoint_seconds > 0 and now - saved >= checkpoint_seconds:
                checkpoint.save(trainer, settings, {"judged": log.state(), "seconds": seconds})
                saved = now
            if progress and now - shown >= PROGRESS_SECONDS:
                steps = int(trainer.steps[0])
                rate = (steps - steps_at_start) / max(time.perf_counter() - clock, 1e-9)
                judged = log.rows[0]["fitness_all"]
                print(
                    f"{time.strftime('%H:%M:%S')} {spec.name}: {steps}/{c.ddpg.max_steps} env "
                    f"steps, {rate:.0f} env steps/s, last judged "
                    f"{judged[-1] if judged else float('nan'):.3f}",
                    file=sys.stderr,
                    flush=True,
                )
                shown = now
        seconds = seconds_before + time.perf_counter() - clock
        record = self.record(spec, result, log, ddpg_seed, seconds)
        json_path, npz_path = self.paths(spec)
        buffer = io.BytesIO()
        np.savez_compressed(
            buffer,
            theta_start=theta,
            omega_start=omega,
            theta_best=result.theta.astype(np.float32),
            omega_best=result.omega.astype(np.float32),
            theta_last_judged=last_theta.get("theta", result.theta).astype(np.float32),
        )
        atomic_write(npz_path, buffer.getvalue())
        write_json(json_path, record, compact=True)
        checkpoint.remove()
        return record

    def record(
        self,
        spec: SearchSpec,
        result: LocalSearchResult,
        log: JudgedLog,
        ddpg_seed: int,
        seconds: float,
    ) -> dict[str, Any]:
        """A finished search as plain data."""
        judged = log.rows[0]
        history = [h for h in result.history if not np.isnan(h.greedy_fitness)]
        steps = [int(h.env_steps) for h in history]
        fitness = [float(h.greedy_fitness) for h in history]
        labels = [LABELS[i] for i in judged["label"]]
        if steps != judged["env_steps"]:
            raise RuntimeError(f"{spec.name}: the judged log and the history disagree")
        return {
            "name": spec.name,
            "arm": spec.arm,
            "p": spec.p,
            "seed_index": spec.seed_index,
            "ddpg_seed": str(ddpg_seed),
            "n_carts": 1 if spec.arm == "control" else 2,
            "start_fitness": float(result.start_fitness),
            "returned_fitness": float(result.fitness),
            "env_steps": int(result.env_steps),
            "stop_reason": result.stop_reason,
            "episodes": len(result.history),
            "seconds": seconds,
            **judged_measures(steps, fitness, labels, self.config),
            "judged_env_steps": steps,
            "judged_fitness": fitness,
            "judged_fitness_all": judged["fitness_all"],
            "judged_fitness_mean": judged["fitness_mean"],
            "judged_label": judged["label"],
            "labels": list(LABELS),
        }

    # ------------------------------------------------------------------ the whole test
    def run(
        self,
        drain_after_seconds: float | None = None,
        checkpoint_seconds: float = 600.0,
        progress: bool = False,
    ) -> tuple[pd.DataFrame, bool]:
        """Run every search not stored yet, in :func:`plan` order; after
        ``drain_after_seconds`` start no new one (each call runs at least one, as ``lonlib run
        --drain-after 0`` does). Writes the tables after every search.
        Returns the summary and whether every search is finished."""
        self.check_settings()
        began, started = time.monotonic(), 0
        for spec in plan(self.config):
            if self.finished(spec) is not None:
                continue
            late = drain_after_seconds is not None and (
                time.monotonic() - began >= drain_after_seconds
            )
            if started and late:
                if progress:
                    print("draining: no new search started", file=sys.stderr, flush=True)
                break
            if progress:
                print(f"{time.strftime('%H:%M:%S')} start {spec.name}", file=sys.stderr, flush=True)
            record = self.run_search(spec, checkpoint_seconds, progress)
            started += 1
            if progress:
                print(
                    f"{time.strftime('%H:%M:%S')} done {spec.name}: last judged "
                    f"{record['last_judged_fitness']}, late share {record['late_share']}, "
                    f"label {record['last_judged_label']}, {record['env_steps']} env steps in "
                    f"{record['seconds']:.0f} s",
                    file=sys.stderr,
                    flush=True,
                )
            self.write_tables()
        summary = self.write_tables()
        done = all(self.finished(spec) is not None for spec in plan(self.config))
        return summary, done

    def records(self) -> list[dict[str, Any]]:
        return [r for spec in plan(self.config) if (r := self.finished(spec)) is not None]

    def write_tables(self) -> pd.DataFrame:
        """``searches.csv`` (one row per finished search), ``summary.csv`` and ``summary.md``
        (one row per arm and p, with the pre-registered verdict)."""
        records = self.records()
        rows = pd.DataFrame(
            [
                {k: v for k, v in r.items() if not k.startswith("judged_") and k != "labels"}
                for r in records
            ]
        )
        summary = summarise(records, self.config)
        self.out.mkdir(parents=True, exist_ok=True)
        atomic_write(self.out / "searches.csv", rows.to_csv(index=False).encode())
        atomic_write(self.out / "summary.csv", summary.to_csv(index=False).encode())
        atomic_write(self.out / "summary.md", summary_markdown(summary, self.config).encode())
        reseal_files_if_sealed(self.out)
        return summary


def summarise(records: list[dict[str, Any]], config: HoldTestConfig) -> pd.DataFrame:
    """One row per arm and p: seeds finished, seeds whose last judged fitness reached
    ``hold_fitness``, the verdict (:func:`held`: ``held``, ``not held`` or ``pending``), the
    last judged fitness per seed, the mean late share, the mean returned fitness and the
    labels at the end."""
    rows = []
    for arm in config.arms:
        for p in config.perturbations:
            mine = sorted(
                (r for r in records if r["arm"] == arm and r["p"] == p),
                key=lambda r: r["seed_index"],
            )
            last = [r["last_judged_fitness"] for r in mine]
            last = [float("nan") if v is None else float(v) for v in last]
            verdict = held(last, config)
            late = [r["late_share"] for r in mine if r["late_share"] is not None]
            labels: dict[str, int] = {}
            for r in mine:
                labels[str(r["last_judged_label"])] = labels.get(str(r["last_judged_label"]), 0) + 1
            rows.append(
                {
                    "arm": arm,
                    "p": p,
                    "seeds_done": len(mine),
                    "held_seeds": sum(v >= config.hold_fitness for v in last),
                    "held": {True: "held", False: "not held", None: "pending"}[verdict],
                    "last_judged": " ".join(f"{v:.4f}" for v in last),
                    "late_share_mean": float(np.mean(late)) if late else None,
                    "returned_mean": float(np.mean([r["returned_fitness"] for r in mine]))
                    if mine
                    else None,
                    "labels_at_end": "; ".join(f"{k} x{n}" for k, n in sorted(labels.items())),
                }
            )
    return pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS))


def summary_markdown(summary: pd.DataFrame, config: HoldTestConfig) -> str:
    """The summary as a Markdown table, with the rule it applies."""
    lines = [
        "| arm | p | seeds done | last judged >= "
        f"{config.hold_fitness:g} | verdict | last judged fitness per seed | late share "
        f"(after {config.late_steps} env steps) | mean returned | labels at the end |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in summary.itertuples(index=False):
        late = "" if pd.isna(row.late_share_mean) else f"{row.late_share_mean:.2f}"
        returned = "" if pd.isna(row.returned_mean) else f"{row.returned_mean:.4f}"
        lines.append(
            f"| {row.arm} | {row.p:g} | {row.seeds_done}/{config.seeds} | {row.held_seeds} | "
            f"{row.held} | {row.last_judged} | {late} | {returned} | {row.labels_at_end} |"
        )
    rule = (
        f"Pre-registered: an arm holds at a p when the last judged fitness is >= "
        f"{config.hold_fitness:g} in >= {config.hold_seeds} of its {config.seeds} seeds."
    )
    return "\n".join([rule, "", *lines, ""])


__all__ = [
    "ARMS",
    "HoldTest",
    "HoldTestConfig",
    "SearchSpec",
    "fit_critic",
    "held",
    "judged_measures",
    "load_hold_config",
    "plan",
    "summarise",
    "summary_markdown",
]
