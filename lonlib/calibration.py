"""Calibration study: which physics lets DDPG leave the zero-fitness plateau, and how.

A study is a grid of **cells**; a cell fixes the motor model (force, acceleration or
velocity), its gain or time constant, the integrator and the DDPG reward. For every cell,
``seeds`` agents train with lonlib's batched DDPG (:func:`lonlib.ddpg.local_search_batch`,
one call per cell) for exactly ``max_steps`` environment steps each (no early stop, so cells
compare at equal budget). Seed ``i`` starts from the same Actor and Critic and draws the same
random streams in every cell (common random numbers), so cells differ only by their physics.

Per search the study reads the training history (greedy fitness after every episode) and
replays the returned Actor greedily once; per cell it reports

* the share of searches **leaving zero** (best greedy fitness of a trained policy > 0),
* the **env steps to the first non-zero** greedy fitness,
* the **best fitness**, and
* **what the best policies do** in their greedy rollout: upright share and signed full
  turns per rod, end reason and step, the range each cart covers, and a behaviour label
  (:func:`behaviour`).

Beside the grid, :func:`integrator_drift` measures each integrator's energy and momentum
drift in a short motor-off, friction-off rollout (force model: the cart is free, so the
cart-and-rod energy and horizontal momentum are both conserved by the continuous equations).

:func:`run_calibration` runs the cells in a process pool (one torch thread per worker) and
writes each finished cell atomically to ``<out>/cells/<cell>.json`` (its Actors to
``<cell>.npz``): a killed study resumes with the cells it has not finished. It then writes
its report (:mod:`lonlib.calibration_report`): ``calibration.csv`` (one row per cell),
``searches.csv`` (one row per search), ``drift.csv``, ``calibration.md`` and
``calibration.png``.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import io
import math
import multiprocessing
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from lonlib.ddpg import DDPGConfig, local_search_batch
from lonlib.nets import actor_spec, critic_spec, forward_numpy
from lonlib.pendulum import (
    CoupledPendulums,
    EndReason,
    PendulumConfig,
    total_energy,
    wrap_angle,
)
from lonlib.progress import progress_bar
from lonlib.store import atomic_write, read_json, write_json
from lonlib.validation import (
    check_choice,
    check_field_types,
    check_name,
    check_range,
    read_yaml_mapping,
)

if TYPE_CHECKING:
    from lonlib.calibration_report import CalibrationResult

MOTORS = ("force", "acceleration", "velocity")
INTEGRATORS = ("euler", "semi-implicit")
REWARDS = ("height", "slow-height", "upright")
CELL_PHYSICS = ("motor", "integrator", "motor_gain", "motor_tau", "reward")
BEHAVIOURS = ("balances", "spins", "swings", "hangs", "ends early")
# Greedy fitness that only balancing reaches: every rod upright >= 90 % of the episode, swing-up
# included (a spinning rod is upright about half the time: no optimum of the default grid, all
# spinning or ending early, scores above 0.51); the study reports the env steps to the first.
BALANCING_FITNESS = 0.9

CELL_COLUMNS = [
    "cell",
    "motor",
    "integrator",
    "motor_gain",
    "motor_tau",
    "reward",
    "searches",
    "left_zero",
    "share_left_zero",
    "first_nonzero_steps_min",
    "first_nonzero_steps_median",
    "first_nonzero_steps_max",
    "balanced",
    "first_balancing_steps_min",
    "first_balancing_steps_median",
    "first_balancing_steps_max",
    "best_fitness",
    "median_best_fitness",
    "behaviours",
    "best_upright_share",
    "best_turns",
    "best_end_reason",
    "best_end_step",
    "best_cart_range",
    "seconds",
]


@dataclass(frozen=True)
class Cell:
    """One physics setting of the grid. ``motor_gain`` matters for the force [N per unit of
    command] and acceleration [m/s^2 per unit] motors, ``motor_tau`` [s] for the velocity
    motor (its gain stays 1: the command range is the +-2 m/s of the velocity sensors)."""

    motor: str = "velocity"
    integrator: str = "semi-implicit"
    motor_gain: float = 1.0
    motor_tau: float = 0.02
    reward: str = "height"

    def __post_init__(self) -> None:
        check_field_types(self)
        check_choice("motor", self.motor, MOTORS)
        check_choice("integrator", self.integrator, INTEGRATORS)
        check_choice("reward", self.reward, REWARDS)
        check_range("motor_gain", self.motor_gain, 0.0, low_open=True)
        check_range("motor_tau", self.motor_tau, 0.0, low_open=True)

    @property
    def name(self) -> str:
        """File-safe, readable name, e.g. ``velocity-tau0.02_semi-implicit_height``."""
        motor = (
            f"velocity-tau{self.motor_tau:g}"
            if self.motor == "velocity"
            else f"{self.motor}-gain{self.motor_gain:g}"
        )
        return f"{motor}_{self.integrator}_{self.reward}"

    def env(self, base: PendulumConfig) -> PendulumConfig:
        """``base`` with this cell's physics (validated by :class:`PendulumConfig`)."""
        return dataclasses.replace(
            base,
            motor=self.motor,
            integrator=self.integrator,
            motor_gain=1.0 if self.motor == "velocity" else self.motor_gain,
            motor_tau=self.motor_tau,
            reward=self.reward,
        )


def grid(
    motors: tuple[str, ...] = MOTORS,
    integrators: tuple[str, ...] = INTEGRATORS,
    force_gains: tuple[float, ...] = (1.0,),
    acceleration_gains: tuple[float, ...] = (1.0,),
    velocity_taus: tuple[float, ...] = (0.02,),
    rewards: tuple[str, ...] = ("height",),
) -> tuple[Cell, ...]:
    """The product of the axes: every motor with each of its gains (or taus), every
    integrator, every reward."""
    settings = {
        "force": [{"motor_gain": g} for g in force_gains],
        "acceleration": [{"motor_gain": g} for g in acceleration_gains],
        "velocity": [{"motor_tau": t} for t in velocity_taus],
    }
    return tuple(
        Cell(motor=motor, integrator=integrator, reward=reward, **setting)
        for motor in motors
        for setting in settings[motor]
        for integrator in integrators
        for reward in rewards
    )


DEFAULT_CELLS = grid(force_gains=(1.0, 5.0), velocity_taus=(0.02, 0.1)) + (
    Cell("velocity", "semi-implicit", motor_tau=0.02, reward="slow-height"),
)
"""Every motor with both integrators and the ``height`` reward (force at 2 N and 10 N,
acceleration at +-2 m/s^2, velocity at tau = 0.02 s and 0.1 s), plus the velocity motor
(tau = 0.02 s, semi-implicit) with the ``slow-height`` reward: 11 cells."""


@dataclass(frozen=True)
class CalibrationConfig:
    """A calibration study: the grid, the seeds per cell and the DDPG budget.

    ``env`` is the physics every cell starts from (cells replace motor, gain, tau,
    integrator and reward); ``ddpg`` holds the other DDPG hyperparameters. Every search
    trains exactly ``max_steps`` env steps with minibatches of ``batch_size``.
    """

    name: str = "default"
    cells: tuple[Cell, ...] = DEFAULT_CELLS
    seeds: int = 3
    seed: int = 0
    max_steps: int = 150_000
    batch_size: int = 256
    env: PendulumConfig = field(default_factory=PendulumConfig)
    ddpg: DDPGConfig = field(default_factory=DDPGConfig)
    drift_steps: int = 2000

    def __post_init__(self) -> None:
        check_field_types(self)
        check_name(self.name)
        if not self.cells or not all(isinstance(c, Cell) for c in self.cells):
            raise ValueError("cells must list at least one Cell")
        names = [cell.name for cell in self.cells]
        if len(set(names)) != len(names):
            raise ValueError(f"cells must not repeat, got {names}")
        check_range("seeds", self.seeds, 1, 1000)
        check_range("seed", self.seed, 0, 2**63 - 1)
        check_range("max_steps", self.max_steps, 1)
        check_range("batch_size", self.batch_size, 1)
        check_range("drift_steps", self.drift_steps, 1, 100_000)
        for cell in self.cells:  # every cell's physics must be valid before any compute
            cell.env(self.env)
        _ = self.hp  # validates the combined DDPG settings

    @property
    def hp(self) -> DDPGConfig:
        """The DDPG settings of every search: a fixed budget of ``max_steps``."""
        return dataclasses.replace(
            self.ddpg,
            batch_size=self.batch_size,
            max_steps=self.max_steps,
            min_steps=self.max_steps,
            patience_steps=self.max_steps,
            warmup_steps=min(self.ddpg.warmup_steps, self.max_steps),
            threads=1,
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain mapping (YAML/JSON friendly) that :meth:`from_mapping` reads back."""
        out = dataclasses.asdict(self)
        out["cells"] = [dataclasses.asdict(cell) for cell in self.cells]
        return out

    def settings(self) -> dict[str, Any]:
        """Everything a stored cell depends on besides the cell itself."""
        out = self.to_dict()
        for key in ("name", "cells", "drift_steps"):
            out.pop(key)
        # Every cell replaces these, so a change of the package's physics defaults must not
        # invalidate stored cells.
        for key in CELL_PHYSICS:
            out["env"].pop(key)
        return out

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> CalibrationConfig:
        """Build from a mapping (YAML): ``base: default|tiny`` starts from a named grid;
        ``env`` and ``ddpg`` list only changed keys; unknown keys are refused by name."""
        values = dict(values)
        base = named_calibration(values.pop("base", "default")).to_dict()
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown calibration key(s) {unknown}; allowed: {sorted(known)}")
        env = {**base.pop("env"), **(values.pop("env", None) or {})}
        ddpg = {**base.pop("ddpg"), **(values.pop("ddpg", None) or {})}
        unknown = sorted(set(ddpg) - {f.name for f in dataclasses.fields(DDPGConfig)})
        if unknown:
            raise ValueError(f"unknown ddpg key(s) {unknown}")
        merged = {**base, **values}
        cell_fields = {f.name for f in dataclasses.fields(Cell)}
        cells = []
        for cell in merged.pop("cells"):
            if not isinstance(cell, dict) or set(cell) - cell_fields:
                raise ValueError(f"a cell must be a mapping of {sorted(cell_fields)}, got {cell!r}")
            cells.append(Cell(**cell))
        return cls(
            cells=tuple(cells),
            env=PendulumConfig.from_mapping(env),
            ddpg=DDPGConfig(**ddpg),
            **merged,
        )


def named_calibration(name: str) -> CalibrationConfig:
    """``default``: the 11 :data:`DEFAULT_CELLS` x 3 seeds x 150k env steps at batch 256 on
    two carts.
    ``tiny``: two cells on one cart with 50-step episodes and 400 env steps per search,
    for tests (seconds)."""
    if name == "default":
        return CalibrationConfig()
    if name == "tiny":
        return CalibrationConfig(
            name="tiny",
            cells=(Cell("velocity", "semi-implicit", motor_tau=0.02), Cell("force", "euler")),
            seeds=2,
            max_steps=400,
            batch_size=32,
            env=PendulumConfig(n_carts=1, steps=50, upright_angle=2.6),
            ddpg=DDPGConfig(buffer_size=500, warmup_steps=50),
            drift_steps=200,
        )
    raise ValueError(f"unknown calibration grid {name!r}; use 'default', 'tiny' or a YAML file")


def load_calibration(spec: str | Path) -> CalibrationConfig:
    """A named grid (``default``, ``tiny``) or a YAML file of :class:`CalibrationConfig`
    keys (``base: default|tiny`` plus changes)."""
    if str(spec) in ("default", "tiny"):
        return named_calibration(str(spec))
    path = Path(spec)
    if not path.is_file():
        raise ValueError(f"calibration grid {spec!r} is neither 'default', 'tiny' nor a file")
    return CalibrationConfig.from_mapping(read_yaml_mapping(path, "calibration"))


def with_overrides(
    config: CalibrationConfig,
    seeds: int | None = None,
    max_steps: int | None = None,
    batch_size: int | None = None,
) -> CalibrationConfig:
    """``config`` with the given seeds, budget and batch (None keeps the grid's own)."""
    changes = {"seeds": seeds, "max_steps": max_steps, "batch_size": batch_size}
    return dataclasses.replace(config, **{k: v for k, v in changes.items() if v is not None})


# ---------------------------------------------------------------------------- rollouts
def greedy_rollout(thetas: np.ndarray, env: PendulumConfig, seed: int = 0) -> pd.DataFrame:
    """What each Actor (row of ``thetas [k, P]``) does in one greedy episode, all ``k``
    batched: fitness, end reason and step, and per rod ``i`` its upright share (steps with
    the rod upright / nominal steps, like the fitness), signed full turns (net rotation /
    2 pi, positive = the tip turning towards +x from upright) and the range its cart covered
    [m]. One row per Actor."""
    thetas = np.atleast_2d(np.asarray(thetas, dtype=np.float32))
    spec = actor_spec(env.n_carts)
    sim = CoupledPendulums(env, len(thetas), seed)
    upright = np.zeros(sim.x.shape)
    angles = [sim.phi.copy()]
    low, high = sim.x.copy(), sim.x.copy()
    cos_upright = math.cos(env.upright_angle)
    while not sim.done.all():
        running = ~sim.done[:, None]
        sim.step(forward_numpy(spec, thetas, sim.observe().astype(np.float32)))
        angles.append(sim.phi.copy())  # an ended environment's angle stays frozen
        upright += running * (np.cos(sim.phi) > cos_upright)
        low, high = np.minimum(low, sim.x), np.maximum(high, sim.x)
    rotation = net_turns(np.stack(angles))
    rows = []
    for b in range(len(thetas)):
        row = {
            "rollout_fitness": float(sim.fitness[b]),
            "end_reason": EndReason(int(sim.end_reason[b])).name.lower(),
            "end_step": int(sim.step_count[b]),
        }
        for i in range(env.n_carts):
            row[f"upright_share_{i}"] = float(upright[b, i] / env.steps)
            row[f"turns_{i}"] = float(rotation[b, i])
            row[f"cart_range_{i}"] = float(high[b, i] - low[b, i])
        row["behaviour"] = behaviour(row, env.n_carts)
        rows.append(row)
    return pd.DataFrame(rows)


def net_turns(angles: np.ndarray) -> np.ndarray:
    """Signed net rotation, in turns, of angle sequences ``[T, ...]`` sampled every step.
    Each step's change is wrapped into (-pi, pi], so a rod must turn less than half a turn
    per step (157 rad/s at dt = 0.02 s; the sensors saturate at 5 pi = 15.7 rad/s)."""
    return wrap_angle(np.diff(angles, axis=0)).sum(axis=0) / (2 * np.pi)


def behaviour(row: dict[str, Any], n_carts: int) -> str:
    """A label of a greedy rollout: ``ends early`` (collision, tether or boundary),
    ``balances`` (every rod upright at least half of the episode and less than one net
    turn: at most a swing-up's worth of rotation), ``spins`` (some rod turned two or more
    full turns), ``hangs`` (no rod ever upright), else ``swings``."""
    turns = [abs(row[f"turns_{i}"]) for i in range(n_carts)]
    shares = [row[f"upright_share_{i}"] for i in range(n_carts)]
    if row["end_reason"] != EndReason.STEP_LIMIT.name.lower():
        return "ends early"
    if min(shares) >= 0.5 and max(turns) < 1.0:
        return "balances"
    if max(turns) >= 2.0:
        return "spins"
    return "swings" if max(shares) > 0 else "hangs"


def integrator_drift(env: PendulumConfig, steps: int = 2000, swing: float = 0.02) -> pd.DataFrame:
    """Energy and momentum drift of each integrator with the motor and friction off.

    One cart (force model, ``env``'s masses, rod and dt), the rod released ``swing`` rad from
    hanging, the cart at rest, ``steps`` control steps on an endless track. The continuous
    equations conserve the energy ``E`` and the horizontal momentum
    ``p = (M + m) x_dot + m l cos(phi) phi_dot``. Reports per integrator the largest
    ``|E - E0|`` [J] and ``|p - p0|`` [kg m/s], the final energy gain above the hanging rest
    relative to the start's, and the swing amplitude over the last tenth of the rollout
    relative to ``swing`` (1 = conserved; a rod that goes over the top reads ~pi / swing).
    """
    rows = []
    for integrator in INTEGRATORS:
        cfg = dataclasses.replace(
            env,
            n_carts=1,
            motor="force",
            integrator=integrator,
            cart_friction=0.0,
            hinge_friction=0.0,
            track_half_length_base=1e9,
            steps=steps,
            initial_noise=0.0,
        )
        m, l, big_m = cfg.pole_mass, cfg.pole_half_length, cfg.cart_mass
        sim = CoupledPendulums(cfg)
        sim.phi[:] = np.pi - swing

        def energy_momentum(sim=sim, cfg=cfg, m=m, l=l, big_m=big_m):
            e = total_energy(cfg, sim.x_dot, sim.phi, sim.phi_dot)[0, 0]
            p = (big_m + m) * sim.x_dot + m * l * np.cos(sim.phi) * sim.phi_dot
            return e, p[0, 0]

        e0, p0 = energy_momentum()
        bottom = -m * cfg.gravity * l
        de = dp = amplitude = 0.0
        for k in range(steps):
            sim.step(np.full((1, 1), 0.5))
            e, p = energy_momentum()
            de, dp = max(de, abs(e - e0)), max(dp, abs(p - p0))
            if k >= steps - max(steps // 10, 1):
                amplitude = max(amplitude, float(np.pi - abs(wrap_angle(sim.phi)[0, 0])))
        rows.append(
            {
                "integrator": integrator,
                "steps": steps,
                "energy_drift": de,
                "momentum_drift": dp,
                "energy_ratio": (e - bottom) / (e0 - bottom),
                "amplitude_ratio": amplitude / swing,
            }
        )
    return pd.DataFrame(rows)


# ---------------------------------------------------------------------------- one cell
def seed_streams(config: CalibrationConfig, index: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Start Actor, start Critic and DDPG seed of search ``index``: the same in every cell."""
    rng = np.random.default_rng([config.seed, index, 0])
    n = config.env.n_carts
    ddpg_seed = int(np.random.SeedSequence([config.seed, index, 1]).generate_state(1)[0])
    return actor_spec(n).initial(rng), critic_spec(n).initial(rng), ddpg_seed


def run_cell(cell: Cell, config: CalibrationConfig) -> tuple[dict[str, Any], np.ndarray]:
    """Train ``config.seeds`` agents on one cell (one batched DDPG call) and describe them.

    Returns the cell record (JSON-ready: the cell, the settings, one entry per search with
    its history and greedy rollout) and the returned Actors ``[seeds, P]``.
    """
    start = time.perf_counter()
    env = cell.env(config.env)
    streams = [seed_streams(config, i) for i in range(config.seeds)]
    thetas = np.stack([s[0] for s in streams])
    omegas = np.stack([s[1] for s in streams])
    results = local_search_batch(thetas, omegas, env, config.hp, [s[2] for s in streams])
    best_thetas = np.stack([r.theta for r in results])
    rollouts = greedy_rollout(best_thetas, env, config.hp.eval_seed)
    searches = []
    for index, (result, rollout) in enumerate(
        zip(results, rollouts.to_dict("records"), strict=True)
    ):
        steps = [h.env_steps for h in result.history]
        fitness = [h.greedy_fitness for h in result.history]
        searches.append(
            {
                "seed_index": index,
                **history_summary(steps, fitness),
                "returned_fitness": result.fitness,
                "start_fitness": result.start_fitness,
                "env_steps": result.env_steps,
                "episodes": len(result.history),
                **rollout,
                "history_env_steps": steps,
                "history_greedy_fitness": fitness,
            }
        )
    record = {
        "cell": dataclasses.asdict(cell),
        "name": cell.name,
        "settings": config.settings(),
        "seconds": time.perf_counter() - start,
        "searches": searches,
    }
    return record, best_thetas


def history_summary(steps: list[int], fitness: list[float]) -> dict[str, Any]:
    """Best greedy fitness of a trained policy (0 if none was judged), the env steps of the
    first non-zero one and of the first at least :data:`BALANCING_FITNESS` (None if never),
    from a search's per-episode history. Episodes before the first update carry no greedy
    fitness (NaN) and are skipped."""
    judged = [(s, f) for s, f in zip(steps, fitness, strict=True) if not math.isnan(f)]
    nonzero = [s for s, f in judged if f > 0]
    balancing = [s for s, f in judged if f >= BALANCING_FITNESS]
    return {
        "best_fitness": max((f for _, f in judged), default=0.0),
        "first_nonzero_steps": nonzero[0] if nonzero else None,
        "first_balancing_steps": balancing[0] if balancing else None,
    }


def cell_paths(out: Path, cell: Cell) -> tuple[Path, Path]:
    """The record (JSON, the commit point) and Actors (npz) of one cell."""
    folder = Path(out) / "cells"
    return folder / f"{cell.name}.json", folder / f"{cell.name}.npz"


def run_and_store_cell(out: str | Path, cell: Cell, config: CalibrationConfig) -> str:
    """Run one cell and write it atomically: the Actors first, then the record."""
    record, thetas = run_cell(cell, config)
    record_path, actors_path = cell_paths(Path(out), cell)

    buffer = io.BytesIO()
    np.savez_compressed(buffer, theta=thetas.astype(np.float32))
    atomic_write(actors_path, buffer.getvalue())
    write_json(record_path, record)
    return cell.name


def read_cell(out: Path, cell: Cell, config: CalibrationConfig) -> dict[str, Any] | None:
    """A stored cell record, None if the cell has not finished. A record made with other
    settings (seeds, budget, base physics) raises ValueError naming the file."""
    path = cell_paths(out, cell)[0]
    if not path.exists():
        return None
    record = read_json(path)
    if record.get("settings") != json_roundtrip(config.settings()):
        raise ValueError(
            f"{path} was computed with other settings than this study's; "
            "use another output folder or the stored settings"
        )
    return record


def json_roundtrip(value: Any) -> Any:
    """``value`` as it reads back from JSON (tuples become lists)."""
    if isinstance(value, dict):
        return {k: json_roundtrip(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_roundtrip(v) for v in value]
    return value


# ---------------------------------------------------------------------------- the study
def run_calibration(
    config: CalibrationConfig, out: str | Path, workers: int = 1, progress: bool = True
) -> CalibrationResult:
    """Run every unfinished cell of ``config`` into ``out`` and write the tables and figure.

    ``workers`` > 1 runs cells in that many processes (one torch thread each; more workers
    than unfinished cells are not started). Finished cells are read back, not recomputed;
    a folder holding cells computed with other settings is refused before any compute.
    """
    check_range("workers", workers, 1, 4096)
    out = Path(out)
    todo = [cell for cell in config.cells if read_cell(out, cell, config) is None]
    write_json(
        out / "calibration.json",
        {"config": config.to_dict(), "updated": datetime.now(UTC).isoformat(timespec="seconds")},
    )
    bar = progress_bar(
        total=len(config.cells),
        initial=len(config.cells) - len(todo),
        desc=f"calibration {config.name}",
        unit="cell",
        disable=not progress,
    )
    try:
        if workers <= 1 or len(todo) <= 1:
            for cell in todo:
                run_and_store_cell(out, cell, config)
                bar.update(1)
        else:
            context = multiprocessing.get_context("spawn")
            with cf.ProcessPoolExecutor(min(workers, len(todo)), mp_context=context) as pool:
                futures = [pool.submit(run_and_store_cell, out, cell, config) for cell in todo]
                for future in cf.as_completed(futures):
                    bar.set_postfix_str(future.result())
                    bar.update(1)
    finally:
        bar.close()
    from lonlib.calibration_report import write_outputs  # it reads the cells stored here

    return write_outputs(config, out)


__all__ = [
    "CELL_COLUMNS",
    "DEFAULT_CELLS",
    "CalibrationConfig",
    "Cell",
    "behaviour",
    "greedy_rollout",
    "grid",
    "integrator_drift",
    "load_calibration",
    "named_calibration",
    "run_calibration",
    "run_cell",
    "with_overrides",
]
