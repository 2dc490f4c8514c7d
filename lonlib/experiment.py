"""Experiments: named configurations -> basin-hopping runs, executed locally or on Dask.

An :class:`ExperimentConfig` expands to ``runs`` independent basin-hopping runs for each
perturbation strength ``p``. Run ``(p, run)`` draws everything from a seed derived from
``(experiment seed, p, run)``, so its result does not depend on where or in what order it
runs. :func:`run_experiment` skips finished runs, continues interrupted ones after their
last stored local search (see :mod:`lonlib.store`) and executes the rest serially, in local
worker processes, or on a Dask cluster.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import multiprocessing
import platform
import subprocess
import zlib
from dataclasses import dataclass, field
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml
from tqdm import tqdm

from lonlib.basin_hopping import (
    BasinHoppingConfig,
    basin_hopping_steps,
    ddpg_local_search,
)
from lonlib.ddpg import DDPGConfig
from lonlib.nets import actor_spec, critic_spec
from lonlib.pendulum import PendulumConfig
from lonlib.progress import progress_bar
from lonlib.store import (
    load_run_state,
    read_experiment_trials,
    read_json,
    read_manifest,
    save_step,
    write_json,
)
from lonlib.validation import check_field_types, check_range

PACKAGES = ("numpy", "torch", "gymnasium", "pandas", "pyarrow", "networkx", "igraph", "dask")


@dataclass(frozen=True)
class ExperimentConfig:
    """One LON sampling experiment: which p values, how many runs, and every setting."""

    name: str = "quick"
    perturbations: tuple[float, ...] = (1e-3, 1e-4)
    runs: int = 4
    tolerance: int = 2
    max_local_searches: int = 6
    seed: int = 2024
    env: PendulumConfig = field(default_factory=PendulumConfig)
    ddpg: DDPGConfig = field(default_factory=DDPGConfig)
    note: str = ""

    def __post_init__(self) -> None:
        check_field_types(self)
        if (
            not isinstance(self.name, str)
            or not self.name.replace("-", "").replace("_", "").isalnum()
        ):
            raise ValueError(f"name must be letters, digits, '-' or '_', got {self.name!r}")
        if not self.perturbations:
            raise ValueError("perturbations must list at least one p > 0")
        for p in self.perturbations:
            if isinstance(p, bool) or not isinstance(p, (int, float)) or not np.isfinite(p):
                raise ValueError(f"perturbations must be numbers, got {p!r}")
            check_range("perturbations", p, 0.0, 10.0, low_open=True)
        if len(set(self.perturbations)) != len(self.perturbations):
            raise ValueError(f"perturbations must not repeat, got {self.perturbations}")
        check_range("runs", self.runs, 1, 1_000_000)
        check_range("seed", self.seed, 0, 2**63 - 1)
        # BasinHoppingConfig validates tolerance and max_local_searches by name.
        self.basin_hopping(self.perturbations[0])

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
        """Build from a mapping, e.g. YAML. ``base: quick|paper`` starts from a named
        configuration; unknown keys are refused by name."""
        values = dict(values)
        base = values.pop("base", None)
        start = named_config(base).to_dict() if base else cls().to_dict()
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown experiment key(s) {unknown}; allowed: {sorted(known)}")
        given = sorted(set(values) - {"name"})
        env = {**start.pop("env"), **(values.pop("env", None) or {})}
        ddpg = {**start.pop("ddpg"), **(values.pop("ddpg", None) or {})}
        merged = {**start, **values}
        if "note" not in values and given:
            merged["note"] = f"based on {base or 'the defaults'}, changed: {', '.join(given)}"
        merged["perturbations"] = tuple(
            _as_float("perturbations", p) for p in merged["perturbations"]
        )
        unknown_ddpg = sorted(set(ddpg) - {f.name for f in dataclasses.fields(DDPGConfig)})
        if unknown_ddpg:
            raise ValueError(f"unknown ddpg key(s) {unknown_ddpg}")
        return cls(env=PendulumConfig.from_mapping(env), ddpg=DDPGConfig(**ddpg), **merged)

    def run_seed(self, p: float, run: int) -> int:
        """Seed of run ``(p, run)``: a pure function of (experiment seed, p, run index)."""
        p_key = zlib.crc32(repr(float(p)).encode())
        return int(np.random.SeedSequence([self.seed, p_key, run]).generate_state(1)[0])

    def comparable(self) -> dict[str, Any]:
        """Everything that must match to add runs or p values to an existing experiment."""
        out = self.to_dict()
        out.pop("runs")
        out.pop("perturbations")
        out.pop("note")
        return out


def _as_float(name: str, value: Any) -> float:
    try:
        return float(value)  # YAML 1.1 reads "1e-3" as a string
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers, got {value!r}") from None


QUICK_DDPG = DDPGConfig(
    batch_size=256,
    buffer_size=20_000,
    warmup_steps=1000,
    max_steps=6000,
    min_steps=3000,
    patience_steps=3000,
)


def named_config(name: str) -> ExperimentConfig:
    """The built-in configurations ``quick`` (minutes; illustrates the pipeline with a shrunk
    DDPG budget, not the paper's experiment) and ``paper`` (the paper's scale)."""
    if name == "quick":
        return ExperimentConfig(
            name="quick",
            perturbations=(1e-3, 1e-4),
            runs=4,
            tolerance=2,
            max_local_searches=6,
            ddpg=QUICK_DDPG,
            note="quick: DDPG budget shrunk (batch 256, <= 6000 env steps per local search); "
            "its LON illustrates the pipeline, it is not the paper's experiment",
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
    raise ValueError(f"unknown configuration {name!r}; use 'quick', 'paper' or a YAML file")


def load_config(spec: str | Path) -> ExperimentConfig:
    """A named configuration or a YAML file path."""
    path = Path(spec)
    if str(spec) in ("quick", "paper"):
        return named_config(str(spec))
    if not path.exists():
        raise ValueError(f"configuration {spec!r} is neither 'quick', 'paper' nor a file")
    try:
        values = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as error:
        raise ValueError(f"{path}: not valid YAML ({error})") from None
    if not isinstance(values, dict):
        raise ValueError(f"{path}: expected a mapping of configuration keys")
    values.setdefault("name", path.stem)
    return ExperimentConfig.from_mapping(values)


# ---------------------------------------------------------------------------- one run
def initial_parameters(config: ExperimentConfig, p: float, run: int) -> tuple[np.ndarray, ...]:
    """Algorithm 2's random initial Actor and Critic for run ``(p, run)``."""
    rng = np.random.default_rng([config.run_seed(p, run), 1])
    n = config.env.n_carts
    return actor_spec(n).initial(rng), critic_spec(n).initial(rng)


def run_one(out: str | Path, config: ExperimentConfig, p: float, run: int) -> dict[str, Any]:
    """Execute (or resume, or skip if finished) run ``(p, run)``, storing every local search.

    Returns a summary: p, run, local searches, best fitness, end reason.
    """
    out = Path(out)
    bh = config.basin_hopping(p)
    state = load_run_state(out, p, run, bh)
    if state is None or not state.finished:
        search = ddpg_local_search(config.env, config.ddpg)
        start = initial_parameters(config, p, run)
        steps = basin_hopping_steps(search, start, bh, config.run_seed(p, run), state)
        for current, _, optimum in steps:
            save_step(out, p, run, current.trials, optimum)
            state = current
    return {
        "p": p,
        "run": run,
        "local_searches": len(state.trials),
        "best_fitness": state.incumbent.fitness if state.incumbent else float("nan"),
        "end_reason": state.end_reason,
    }


# ---------------------------------------------------------------------------- manifest
def _git_commit() -> str | None:
    try:
        return subprocess.run(
            ["git", "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
            cwd=Path(__file__).parent,
            timeout=5,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None


def _versions() -> dict[str, str | None]:
    out = {"python": platform.python_version()}
    for name in ("lonlib", *PACKAGES):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def updated_manifest(config: ExperimentConfig, out: Path) -> dict[str, Any]:
    """The manifest ``out`` should hold for ``config`` (new, or the stored one with this
    session added); refuses a folder holding another experiment. Writes nothing."""
    path = out / "manifest.json"
    now = datetime.now(UTC).isoformat(timespec="seconds")
    if path.exists():
        manifest = read_json(path)
        stored = ExperimentConfig.from_mapping(manifest["config"])
        if stored.comparable() != config.comparable():
            changed = sorted(
                k for k in config.comparable() if stored.comparable()[k] != config.comparable()[k]
            )
            raise ValueError(
                f"{out} holds an experiment with a different configuration ({changed} differ); "
                "choose another output folder or use the stored configuration"
            )
        runs = max(stored.runs, config.runs)
        perturbations = tuple(dict.fromkeys((*stored.perturbations, *config.perturbations)))
        merged = dataclasses.replace(stored, runs=runs, perturbations=perturbations)
        manifest["config"] = merged.to_dict()
        manifest.setdefault("sessions", []).append(
            {"started": now, "versions": _versions(), "git_commit": _git_commit()}
        )
    else:
        manifest = {
            "experiment": config.name,
            "created": now,
            "config": config.to_dict(),
            "lonlib_version": _versions()["lonlib"],
            "git_commit": _git_commit(),
            "versions": _versions(),
            "host": platform.node(),
            "sessions": [{"started": now}],
        }
    return manifest


# ---------------------------------------------------------------------------- executors
def pending_runs(config: ExperimentConfig, out: Path) -> list[tuple[float, int]]:
    """Runs that are not finished yet (reads every stored run; corrupt files raise)."""
    pending = []
    for p in config.perturbations:
        bh = config.basin_hopping(p)
        for run in range(config.runs):
            state = load_run_state(out, p, run, bh)
            if state is None or not state.finished:
                pending.append((p, run))
    return pending


def run_experiment(
    config: ExperimentConfig,
    out: str | Path,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    max_attempts: int = 3,
) -> pd.DataFrame:
    """Run every unfinished run of ``config`` into ``out``; return all trials.

    ``workers`` <= 1 and no scheduler: in this process. ``workers`` > 1: that many local
    worker processes (one torch thread each). ``scheduler``: a Dask scheduler address, or
    ``"dask-local"`` for a LocalCluster of ``workers`` processes. A run whose worker dies is
    retried (up to ``max_attempts``) and resumes from its last stored local search.
    """
    check_range("workers", workers, 1, 4096)
    out = Path(out)
    manifest = updated_manifest(config, out)
    todo = pending_runs(config, out)  # reads every stored run: a corrupt file stops us here
    write_json(out / "manifest.json", manifest)
    total = len(config.perturbations) * config.runs
    bar = progress_bar(
        total=total,
        initial=total - len(todo),
        desc=f"{config.name} runs",
        disable=not progress,
        unit="run",
    )
    try:
        if not todo:
            pass
        elif scheduler is not None:
            _run_dask(config, out, todo, workers, scheduler, bar, max_attempts)
        elif workers <= 1:
            for p, run in todo:
                run_one(out, config, p, run)
                _refresh(bar, out, done=1)
        else:
            _run_pool(config, out, todo, workers, bar, max_attempts)
    finally:
        bar.close()
    return read_experiment_trials(out)


def _refresh(bar: tqdm, out: Path, done: int = 0) -> None:
    """Advance the progress bar and show local searches and the best fitness so far."""
    if bar.disable:
        return
    bar.update(done)
    trials = read_experiment_trials(out)
    if len(trials):
        bar.set_postfix(local_searches=len(trials), best=f"{trials['fitness'].max():.3f}")


def _run_pool(config, out, todo, workers, bar, max_attempts) -> None:
    attempts = dict.fromkeys(todo, 0)
    remaining = list(todo)
    while remaining:
        context = multiprocessing.get_context("spawn")
        broken: list[tuple[float, int]] = []
        with cf.ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
            futures = {pool.submit(run_one, out, config, p, run): (p, run) for p, run in remaining}
            pending = set(futures)
            while pending:
                done, pending = cf.wait(pending, timeout=5, return_when=cf.FIRST_COMPLETED)
                for future in done:
                    key = futures[future]
                    try:
                        future.result()
                        _refresh(bar, out, done=1)
                    except cf.process.BrokenProcessPool:
                        broken.append(key)
                _refresh(bar, out)
        for key in broken:
            attempts[key] += 1
            if attempts[key] >= max_attempts:
                raise RuntimeError(f"run p={key[0]} run={key[1]} failed {max_attempts} times")
        remaining = broken


def _run_dask(config, out, todo, workers, scheduler, bar, max_attempts) -> None:
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler == "dask-local":
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
        )
        client = Client(cluster)
    else:
        client = Client(scheduler, timeout="30s")
    try:
        futures = [
            client.submit(
                run_one,
                str(out),
                config,
                p,
                run,
                key=f"{config.name}-{p}-{run}",
                retries=max_attempts - 1,
                pure=False,
            )
            for p, run in todo
        ]
        for future in as_completed(futures):
            future.result()
            _refresh(bar, out, done=1)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def status(out: str | Path) -> pd.DataFrame:
    """Per p: runs finished, started (interrupted or running), not started; local searches,
    best fitness. Reads the manifest for the planned runs."""
    out = Path(out)
    manifest = read_manifest(out)
    config = ExperimentConfig.from_mapping(manifest["config"])
    rows = []
    for p in config.perturbations:
        bh = config.basin_hopping(p)
        finished = started = searches = 0
        best = float("nan")
        for run in range(config.runs):
            state = load_run_state(out, p, run, bh)
            if state is None:
                continue
            searches += len(state.trials)
            finished += state.finished
            started += not state.finished
            if state.incumbent is not None:
                best = np.fmax(best, state.incumbent.fitness)
        rows.append(
            {
                "p": p,
                "runs": config.runs,
                "finished": finished,
                "started": started,
                "not_started": config.runs - finished - started,
                "local_searches": searches,
                "best_fitness": best,
            }
        )
    return pd.DataFrame(rows)
