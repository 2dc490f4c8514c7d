"""Calibration study: which physics lets DDPG leave the zero-fitness plateau, and how.

A study is a grid of **cells**; a cell fixes the motor model (force, acceleration or
velocity), its gain or time constant, the integrator and the DDPG reward. For every cell,
``seeds`` agents train with lonlib's batched DDPG (one :class:`lonlib.ddpg.trainer.SlotTrainer`
per cell) for exactly ``max_steps`` environment steps each (no early stop, so cells
compare at equal budget). Seed ``i`` starts from the same Actor and Critic and draws the same
random streams in every cell (common random numbers), so cells differ only by their physics.

Per search the study reads the training history (greedy fitness after every episode) and
replays the returned Actor greedily once; per cell it reports

* the share of searches **leaving zero** (best greedy fitness of a trained policy > 0),
* the **env steps to the first non-zero** greedy fitness,
* the **best fitness**, and
* **what the best policies do** in their greedy rollout (:func:`greedy_rollout`, the
  behaviour descriptor of :mod:`lonlib.task.behaviour`): upright share and signed full turns per
  rod, end reason and step, the carts' mean range, the fitness from perturbed starts, and
  the behaviour label (one of :data:`lonlib.task.behaviour.LABELS`).

Beside the grid, :func:`integrator_drift` measures each integrator's energy and momentum
drift in a short motor-off, friction-off rollout (force model: the cart is free, so the
cart-and-rod energy and horizontal momentum are both conserved by the continuous equations).
Every episode here runs through the one rollout (:func:`lonlib.task.rollout.run_policy`).

:func:`run_calibration` runs the cells in a process pool (one torch thread per worker) and
writes each finished cell atomically to ``<out>/cells/<cell>.json`` (its Actors to
``<cell>.npz``): a killed study resumes with the cells it has not finished. It then writes
its report (:mod:`lonlib.calibration.report`): ``calibration.csv`` (one row per cell),
``searches.csv`` (one row per search), ``drift.csv``, ``calibration.md`` and
``calibration.png``.

**Learner-side cells** (the two-cart study, ``configs/study-two-cart.yaml``): a cell may
also set ``exploring_starts`` (training episodes start from
:class:`StartSpread`, the greedy evaluations keep Algorithm 1's start) and ``continue_from``
(its searches start from the best Actor and Critic that search ``i`` of an earlier cell
stored, with fresh replay buffers, Adam state and random streams: a basin-hopping chain's
situation); the ``height-product`` reward is a :class:`lonlib.task.pendulum.PendulumConfig`
reward. Every judged policy of a search is also described (:func:`judged_summary`): its
nominal episode's fitness under both aggregations and its behaviour label. A cell's
searches train with in-flight checkpoints (:mod:`lonlib.calibration.inflight`): a killed
study resumes mid-cell and gives the same cells as an uninterrupted one.
"""

from __future__ import annotations

import dataclasses
import io
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from lonlib.calibration.inflight import CellCheckpoint
from lonlib.ddpg.trainer import LocalSearchResult, SlotTrainer
from lonlib.storage.atomic import atomic_write, read_json, write_json
from lonlib.storage.configs import DDPGConfig, without_default_judging
from lonlib.task.behaviour import LABELS, describe_actors, describe_rollout, label
from lonlib.task.pendulum import PendulumConfig, total_energy, wrap_angle
from lonlib.task.policy import actor_spec, critic_spec
from lonlib.task.rollout import Rollout, Scoring, run_policy
from lonlib.util import portable_math
from lonlib.util.validation import (
    check_choice,
    check_field_types,
    check_name,
    check_range,
    read_yaml_mapping,
)

MOTORS = ("force", "acceleration", "velocity")
INTEGRATORS = ("euler", "semi-implicit")
REWARDS = ("height", "slow-height", "height-product", "upright")
CELL_PHYSICS = ("motor", "integrator", "motor_gain", "motor_tau", "reward")
# Version of what a stored cell's searches hold; part of the settings, so that cells stored
# before the one rollout and behaviour descriptor (per-cart ``cart_range_<i>``, the study's
# own labels, other arithmetic) are refused rather than mixed with new ones.
RECORD_FORMAT = 2
# Greedy fitness that only balancing reaches: every rod upright >= 90 % of the episode, swing-up
# included (a spinning rod is upright about half the time: no optimum of the default grid, all
# spinning or ending early, scores above 0.51); the study reports the env steps to the first.
BALANCING_FITNESS = 0.9
# The labels of an optimum with at least one rod balanced (lonlib.task.behaviour.label).
ROD_UP_LABELS = ("balancing", "one rod up")
PROGRESS_SECONDS = 300.0  # at most one progress line per cell this often
AGGREGATIONS = ("all", "mean")  # fitness_mode: every rod upright per step, the upright share

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
class StartSpread:
    """Where the training episodes of a cell with ``exploring_starts`` start: the nominal
    start (carts at rest, evenly spaced, rods at ``initial_angle``) plus U[-w, w] on each
    coordinate of every cart, drawn per episode from the search's start-noise stream. The
    default spreads the angle over the whole circle and the angular velocity over
    +-pi rad/s (half a turn per second: slow enough to be caught near upright), carts at
    rest at their nominal places. Training only: the greedy evaluations (the fitness)
    start from Algorithm 1's fixed start."""

    position: float = 0.0
    """Half-width w of the cart position noise [m], in [0, 0.4] (carts stay apart)."""
    velocity: float = 0.0
    """Half-width of the cart velocity noise [m/s], in [0, 2]."""
    angle: float = math.pi
    """Half-width of the rod angle noise [rad], in [0, pi] (pi: the whole circle)."""
    angular_velocity: float = math.pi
    """Half-width of the rod angular velocity noise [rad/s], in [0, 5 pi]."""

    def __post_init__(self) -> None:
        check_field_types(self)
        check_range("starts.position", self.position, 0.0, 0.4)
        check_range("starts.velocity", self.velocity, 0.0, 2.0)
        check_range("starts.angle", self.angle, 0.0, math.pi)
        check_range("starts.angular_velocity", self.angular_velocity, 0.0, 5 * math.pi)

    @property
    def half_widths(self) -> tuple[float, float, float, float]:
        """``(x, x_dot, phi, phi_dot)`` half-widths, the order of the simulator's state."""
        return (self.position, self.velocity, self.angle, self.angular_velocity)


@dataclass(frozen=True)
class Cell:
    """One physics setting of the grid. ``motor_gain`` scales every motor's command: N per
    unit for the force motor, m/s^2 for the acceleration motor, m/s for the velocity motor
    (1 by default: the command range is the +-2 m/s of the velocity sensors; 0.5 a slower
    motor of +-1 m/s); ``motor_tau`` [s] is the velocity motor's lag."""

    motor: str = "velocity"
    """Motor model of the carts: ``force``, ``acceleration`` or ``velocity``."""
    integrator: str = "semi-implicit"
    """Integrator of the physics: ``euler`` or ``semi-implicit``."""
    motor_gain: float = 1.0
    """Force [N], acceleration [m/s^2] or target speed [m/s] per unit of command (name
    suffix ``-gain<g>`` on a velocity motor whose gain is not 1)."""
    motor_tau: float = 0.02
    """Time constant [s] of the velocity motor's response to its command."""
    reward: str = "height"
    """Reward of the training episodes (:data:`REWARDS`, e.g. ``height``, ``slow-height``)."""
    exploring_starts: bool = False
    """Training episodes start from the study's :class:`StartSpread` (name suffix
    ``_explore``)."""
    continue_from: str = ""
    """Name of an earlier cell of the grid whose searches' best Actors and Critics this
    cell's searches start from (name suffix ``_continue``); empty: the study's starts."""
    initial_angle: float = math.pi
    """Rod angle [rad] at the start of every episode, training and greedy (hence the
    fitness), in [0, 2 pi): pi, hanging (Algorithm 1's start); 0, upright, a balance-only
    task that separates holding the rods up from swinging them up (name suffix
    ``_upright-start``; another angle ``_start<angle>``)."""

    def __post_init__(self) -> None:
        check_field_types(self)
        if not 0.0 <= self.initial_angle < 2 * math.pi:
            raise ValueError(f"initial_angle must be in [0, 2 pi), got {self.initial_angle!r}")
        check_choice("motor", self.motor, MOTORS)
        check_choice("integrator", self.integrator, INTEGRATORS)
        check_choice("reward", self.reward, REWARDS)
        check_range("motor_gain", self.motor_gain, 0.0, low_open=True)
        check_range("motor_tau", self.motor_tau, 0.0, low_open=True)

    @property
    def name(self) -> str:
        """File-safe, readable name, e.g. ``velocity-tau0.02_semi-implicit_height``
        (``_upright-start``, ``_explore``, ``_continue`` appended for those kinds)."""
        if self.motor != "velocity":
            motor = f"{self.motor}-gain{self.motor_gain:g}"
        elif self.motor_gain == 1.0:  # the name cells stored before the gain was a setting keep
            motor = f"velocity-tau{self.motor_tau:g}"
        else:
            motor = f"velocity-tau{self.motor_tau:g}-gain{self.motor_gain:g}"
        kinds = "_explore" * self.exploring_starts + "_continue" * bool(self.continue_from)
        return f"{motor}_{self.integrator}_{self.reward}{self.start_suffix}{kinds}"

    def to_dict(self) -> dict[str, Any]:
        """The cell's fields as stored: ``initial_angle`` only when it is not hanging, so
        that cells stored before it was a setting keep their identity."""
        out = dataclasses.asdict(self)
        if self.initial_angle == math.pi:
            out.pop("initial_angle")
        return out

    @property
    def start_suffix(self) -> str:
        """The name's mark of a start other than hanging: ``_upright-start`` or
        ``_start<angle>``; empty for Algorithm 1's hanging start."""
        if self.initial_angle == math.pi:
            return ""
        return "_upright-start" if self.initial_angle == 0.0 else f"_start{self.initial_angle:.3g}"

    def env(self, base: PendulumConfig) -> PendulumConfig:
        """``base`` with this cell's physics (validated by :class:`PendulumConfig`)."""
        return dataclasses.replace(
            base,
            motor=self.motor,
            integrator=self.integrator,
            motor_gain=self.motor_gain,
            motor_tau=self.motor_tau,
            reward=self.reward,
            initial_angle=self.initial_angle,
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
    """Study name: the folder's default name."""
    cells: tuple[Cell, ...] = DEFAULT_CELLS
    """The grid: one cell per motor, gain or tau, integrator and reward."""
    seeds: int = 3
    """DDPG searches per cell."""
    seed: int = 0
    """Study seed: search ``k`` of a cell is seeded from it."""
    max_steps: int = 150_000
    """Environment steps every search trains (no early stop)."""
    batch_size: int = 256
    """DDPG minibatch size of every search."""
    env: PendulumConfig = field(default_factory=PendulumConfig)
    """The physics every cell starts from (cells replace motor, gain, tau, integrator, reward)."""
    ddpg: DDPGConfig = field(default_factory=DDPGConfig)
    """The other DDPG hyperparameters."""
    drift_steps: int = 2000
    """Steps of the motor-off energy-drift check of each integrator."""
    starts: StartSpread = field(default_factory=StartSpread)
    """Where the training episodes of cells with ``exploring_starts`` start."""

    def __post_init__(self) -> None:
        check_field_types(self)
        check_name(self.name)
        if not self.cells or not all(isinstance(c, Cell) for c in self.cells):
            raise ValueError("cells must list at least one Cell")
        names = [cell.name for cell in self.cells]
        for index, name in enumerate(names):
            if name in names[:index]:
                raise ValueError(
                    f"cells[{index}] repeats cells[{names.index(name)}] ({name}); "
                    "cells must not repeat"
                )
        check_range("seeds", self.seeds, 1, 1000)
        check_range("seed", self.seed, 0, 2**63 - 1)
        check_range("max_steps", self.max_steps, 1)
        check_range("batch_size", self.batch_size, 1)
        check_range("drift_steps", self.drift_steps, 1, 100_000)
        if self.env.initial_angle != math.pi:
            raise ValueError(
                f"env.initial_angle must be pi (hanging; each cell sets its own start: "
                f"cells[i].initial_angle), got {self.env.initial_angle!r}"
            )
        for index, cell in enumerate(self.cells):  # each cell's physics, before any compute
            try:
                cell.env(self.env)
            except ValueError as error:
                raise ValueError(f"cells[{index}]: {error}") from error
        for index, cell in enumerate(self.cells):
            earlier = names[:index]
            if cell.continue_from and cell.continue_from not in earlier:
                raise ValueError(
                    f"cells[{index}].continue_from must name an earlier cell of the grid "
                    f"(one of {earlier}), got {cell.continue_from!r}"
                )
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
        out["cells"] = [cell.to_dict() for cell in self.cells]
        return out

    def cell(self, name: str) -> Cell:
        """The cell of the grid named ``name``."""
        return {cell.name: cell for cell in self.cells}[name]

    def cell_settings(self, cell: Cell) -> dict[str, Any]:
        """Everything one stored cell depends on besides the cell itself: :meth:`settings`,
        plus the start spread of an exploring cell and the source cell of a continuing one
        (so that cells of the former kinds keep the settings they were stored with)."""
        out = self.settings()
        if cell.exploring_starts:
            out["starts"] = dataclasses.asdict(self.starts)
        if cell.continue_from:
            source = self.cell(cell.continue_from)
            out["source"] = {"cell": source.to_dict(), **self.cell_settings(source)}
        return out

    def settings(self) -> dict[str, Any]:
        """Everything a stored cell depends on besides the cell itself."""
        out = self.to_dict()
        for key in ("name", "cells", "drift_steps", "starts"):
            out.pop(key)
        # Every cell replaces these, so a change of the package's physics defaults must not
        # invalidate stored cells.
        for key in CELL_PHYSICS:
            out["env"].pop(key)
        out["record_format"] = RECORD_FORMAT
        out["ddpg"] = without_default_judging(out["ddpg"])
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
        starts = {**base.pop("starts"), **(values.pop("starts", None) or {})}
        unknown = sorted(set(starts) - {f.name for f in dataclasses.fields(StartSpread)})
        if unknown:
            raise ValueError(f"unknown starts key(s) {unknown}")
        unknown = sorted(set(ddpg) - {f.name for f in dataclasses.fields(DDPGConfig)})
        if unknown:
            raise ValueError(f"unknown ddpg key(s) {unknown}")
        merged = {**base, **values}
        cell_fields = {f.name for f in dataclasses.fields(Cell)}
        cells = []
        listed = merged.pop("cells")
        if not isinstance(listed, (list, tuple)):
            raise ValueError(f"cells must be a list of mappings (one per cell), got {listed!r}")
        for index, cell in enumerate(listed):
            if not isinstance(cell, dict) or set(cell) - cell_fields:
                raise ValueError(
                    f"cells[{index}] must be a mapping of {sorted(cell_fields)}, got {cell!r}"
                )
            try:
                cells.append(Cell(**cell))
            except ValueError as error:  # name the cell the field belongs to
                raise ValueError(f"cells[{index}].{error}") from error
        return cls(
            cells=tuple(cells),
            env=PendulumConfig.from_mapping(env),
            ddpg=DDPGConfig(**ddpg),
            starts=StartSpread(**starts),
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
def greedy_rollout(
    thetas: np.ndarray, env: PendulumConfig, scoring: Scoring | int | None = None
) -> pd.DataFrame:
    """What each Actor (row of ``thetas [k, P]``) does in its greedy episode: one row per
    Actor, from :func:`lonlib.task.behaviour.describe_actors` (one batched rollout).

    Columns: ``rollout_fitness`` (Algorithm 1 under the config's ``fitness_mode``, from the
    nominal start: the fitness the search compared), ``fitness_all`` and ``fitness_mean``
    (the same episode under both aggregations), ``end_reason`` (lower-case
    :class:`~lonlib.task.pendulum.EndReason` name) and ``end_step`` (steps executed); per rod
    ``i`` ``upright_share_<i>`` (steps with the rod upright / steps **executed**, not the
    nominal steps the fitness divides by: a rod upright throughout an episode that ended
    early reads 1) and ``turns_<i>`` (signed full turns); ``cart_range`` (max x - min x
    [m], mean over carts); ``robust_mean`` and ``robust_min`` (the fitness from the
    scoring's perturbed starts); ``behaviour`` (:func:`lonlib.task.behaviour.label`).

    ``scoring`` gives the starts (:class:`lonlib.task.rollout.Scoring`, default ``Scoring()``);
    an int is read as the nominal start's ``eval_seed`` (the former ``seed`` argument).
    """
    if scoring is None:
        scoring = Scoring()
    elif not isinstance(scoring, Scoring):
        scoring = Scoring(eval_seed=int(scoring))
    descriptors = describe_actors(np.atleast_2d(np.asarray(thetas)), env, scoring)
    rows = []
    for d in descriptors:
        row: dict[str, Any] = {
            "rollout_fitness": d.fitness,
            "fitness_all": d.fitness_all,
            "fitness_mean": d.fitness_mean,
            "end_reason": d.end_reason.lower(),
            "end_step": d.end_step,
        }
        for i, (share, turns) in enumerate(zip(d.upright_share, d.turns, strict=True)):
            row[f"upright_share_{i}"] = share
            row[f"turns_{i}"] = turns
        row.update(
            {
                "cart_range": d.cart_range,
                "robust_mean": d.robust_mean,
                "robust_min": d.robust_min,
                "behaviour": label(d),
            }
        )
        rows.append(row)
    return pd.DataFrame(rows)


def _motor_off(observation: np.ndarray) -> np.ndarray:
    """The constant policy of :func:`integrator_drift`: command 0.5, no force."""
    return np.full((len(observation), 1), 0.5)


def integrator_drift(env: PendulumConfig, steps: int = 2000, swing: float = 0.02) -> pd.DataFrame:
    """Energy and momentum drift of each integrator with the motor and friction off.

    One cart (force model, ``env``'s masses, rod and dt), the rod released ``swing`` rad from
    hanging, the cart at rest, ``steps`` control steps on an endless track, run by the one
    rollout (:func:`lonlib.task.rollout.run_policy`, traced) with a constant zero-force command.
    The continuous equations conserve the energy ``E`` and the horizontal momentum
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
            initial_angle=math.pi,
        )
        m, l, big_m = cfg.pole_mass, cfg.pole_half_length, cfg.cart_mass
        offsets = np.zeros((4, 1, 1))
        offsets[2] = -swing  # phi = pi - swing: released from rest
        trace = run_policy(_motor_off, cfg, offsets, trace=True).trace
        # the start, then the state after every step, of the one episode: [steps + 1]
        x_dot = np.concatenate([[0.0], trace.x_dot[:, 0, 0]])
        phi = np.concatenate([[math.pi - swing], trace.phi[:, 0, 0]])
        phi_dot = np.concatenate([[0.0], trace.phi_dot[:, 0, 0]])
        if len(phi) != steps + 1:
            raise RuntimeError(f"the drift rollout ended after {len(phi) - 1} of {steps} steps")
        energy = total_energy(cfg, x_dot, phi, phi_dot)
        momentum = (big_m + m) * x_dot + m * l * portable_math.cos(phi) * phi_dot
        bottom = -m * cfg.gravity * l
        tail = phi[1 + steps - max(steps // 10, 1) :]
        rows.append(
            {
                "integrator": integrator,
                "steps": steps,
                "energy_drift": float(np.max(np.abs(energy[1:] - energy[0]))),
                "momentum_drift": float(np.max(np.abs(momentum[1:] - momentum[0]))),
                "energy_ratio": float((energy[-1] - bottom) / (energy[0] - bottom)),
                "amplitude_ratio": float(np.max(np.pi - np.abs(wrap_angle(tail)))) / swing,
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


def continue_seed(config: CalibrationConfig, index: int) -> int:
    """DDPG seed of search ``index`` of a ``continue_from`` cell: fresh streams, as a
    basin-hopping trial's local search draws its own."""
    return int(np.random.SeedSequence([config.seed, index, 2]).generate_state(1)[0])


class JudgedLog:
    """Every judged policy of a cell's searches, described: the trainer's ``on_judged``.

    Per search (the trainer's tags are the seed indices) four lists in judge order (episode
    order): the env steps at the episode's end, the nominal episode's fitness under both
    aggregations (``fitness_all``, ``fitness_mean``) and the behaviour label's index in
    :data:`lonlib.task.behaviour.LABELS`. Each is read from the judge's own traced nominal
    episode (:func:`lonlib.task.behaviour.describe_rollout`): no policy is rolled out twice.
    """

    def __init__(self, env: PendulumConfig, searches: int) -> None:
        self.env = env
        self.rows: dict[int, dict[str, list]] = {
            i: {"env_steps": [], "fitness_all": [], "fitness_mean": [], "label": []}
            for i in range(searches)
        }

    def __call__(self, judged: list[tuple[Any, Any, np.ndarray]], nominal: Rollout) -> None:
        """Log a batch of ``(tag, EpisodeRecord, flat Actor)`` described from ``nominal``,
        the judge's traced nominal episodes (row ``j``: entry ``j``)."""
        for row, (tag, record, _) in enumerate(judged):
            d = describe_rollout(nominal, self.env, row)
            rows = self.rows[int(tag)]
            rows["env_steps"].append(int(record.env_steps))
            rows["fitness_all"].append(d.fitness_all)
            rows["fitness_mean"].append(d.fitness_mean)
            rows["label"].append(LABELS.index(label(d)))

    def state(self) -> dict[str, Any]:
        """Plain data (JSON): what :meth:`restore` reads back."""
        return {str(i): rows for i, rows in self.rows.items()}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state`'s data."""
        if set(state) != {str(i) for i in self.rows}:
            raise ValueError(f"judged log of searches {sorted(state)}, expected {len(self.rows)}")
        self.rows = {int(i): {k: list(v) for k, v in rows.items()} for i, rows in state.items()}


def cell_starts(
    cell: Cell, config: CalibrationConfig, out: str | Path | None
) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Start Actors ``[seeds, P]``, Critics and DDPG seeds of a cell's searches: the
    study's (:func:`seed_streams`), or for a ``continue_from`` cell the best Actors and
    Critics its source cell stored in ``out`` with fresh seeds (:func:`continue_seed`).
    ValueError, naming the field, if the source cell has not stored them."""
    if not cell.continue_from:
        streams = [seed_streams(config, i) for i in range(config.seeds)]
        return (
            np.stack([s[0] for s in streams]),
            np.stack([s[1] for s in streams]),
            [s[2] for s in streams],
        )
    source = config.cell(cell.continue_from)
    path = cell_paths(Path(out or "."), source)[1]
    if out is None or read_cell(Path(out), source, config) is None or not path.exists():
        raise ValueError(
            f"continue_from: the source cell {source.name!r} has not stored its searches in "
            f"{out}; it must finish first (it is an earlier cell of the grid)"
        )
    with np.load(path) as data:
        if "omega" not in data:
            raise ValueError(
                f"continue_from: {path} holds no Critics (stored before the study kept them); "
                f"recompute the cell {source.name!r}"
            )
        thetas, omegas = data["theta"], data["omega"]
    if len(thetas) != config.seeds:
        raise ValueError(f"continue_from: {path} holds {len(thetas)} searches, not {config.seeds}")
    return thetas, omegas, [continue_seed(config, i) for i in range(config.seeds)]


class CellParameters(NamedTuple):
    """The best Actors and Critics of a cell's searches (float32, one row per search)."""

    theta: np.ndarray
    omega: np.ndarray


def run_cell(
    cell: Cell,
    config: CalibrationConfig,
    out: str | Path | None = None,
    *,
    checkpoint_seconds: float = 600.0,
    check_steps: int = 1000,
    progress: bool = False,
) -> tuple[dict[str, Any], CellParameters]:
    """Train ``config.seeds`` agents on one cell (one batch of lockstep searches) and
    describe them.

    Returns the cell record (JSON-ready: the cell, the settings, one entry per search with
    its history, the described judged policies and the greedy rollout of its returned
    Actor), and the returned Actors ``[seeds, P]`` and Critics (:class:`CellParameters`).
    With ``out`` (the study folder) the batch is checkpointed every ``checkpoint_seconds``
    (checked every ``check_steps`` env steps;
    :class:`lonlib.calibration.inflight.CellCheckpoint`) and a
    checkpoint found there is continued: the record is the same as an uninterrupted run's
    (``seconds`` aside). ``progress`` prints a line at most every :data:`PROGRESS_SECONDS` (env
    steps per search, env steps/s, best greedy fitness so far).
    """
    check_range("checkpoint_seconds", checkpoint_seconds, 0.0)
    check_range("check_steps", check_steps, 1)
    start = time.perf_counter()
    env = cell.env(config.env)
    hp = config.hp
    settings = {"cell": cell.to_dict(), **config.cell_settings(cell)}
    log = JudgedLog(env, config.seeds)
    checkpoint = CellCheckpoint(out, cell.name) if out is not None else None
    restored = checkpoint.load(settings) if checkpoint else None
    spread = config.starts.half_widths if cell.exploring_starts else None
    if restored is None:
        thetas, omegas, seeds = cell_starts(cell, config, out)
        trainer = SlotTrainer(thetas, omegas, seeds, env, hp, start_spread=spread)
        trained_seconds = 0.0
    else:
        trainer, state = restored
        trainer.start_spread = spread
        log.restore(state["judged"])
        trained_seconds = float(state["seconds"])
    trainer.on_judged = log
    results: list[LocalSearchResult | None] = [None] * config.seeds
    steps_at_start, clock, shown = int(trainer.steps.max()), time.monotonic(), 0.0
    saved = clock
    while trainer.busy.any():
        for tag, result in trainer.step():
            results[tag] = result
        steps = int(trainer.steps.max())
        if steps % check_steps or not trainer.busy.all():
            continue
        now = time.monotonic()
        if checkpoint is not None and now - saved >= checkpoint_seconds:
            seconds = trained_seconds + time.perf_counter() - start
            checkpoint.save(trainer, settings, {"judged": log.state(), "seconds": seconds})
            saved = now
        if progress and now - shown >= PROGRESS_SECONDS:
            rate = config.seeds * (steps - steps_at_start) / max(now - clock, 1e-9)
            best = max(r.fitness for r in trainer.results())
            print(
                f"{time.strftime('%H:%M:%S')} {cell.name}: {steps}/{config.max_steps} env steps "
                f"per search, {rate:.0f} env steps/s, best greedy fitness {best:.3f}",
                file=sys.stderr,
                flush=True,
            )
            shown = now
    best_thetas = np.stack([r.theta for r in results])
    best_omegas = np.stack([r.omega for r in results])
    rollouts = greedy_rollout(best_thetas, env, hp.scoring)
    searches = []
    for index, (result, rollout) in enumerate(
        zip(results, rollouts.to_dict("records"), strict=True)
    ):
        steps = [h.env_steps for h in result.history]
        fitness = [h.greedy_fitness for h in result.history]
        judged = log.rows[index]
        searches.append(
            {
                "seed_index": index,
                **history_summary(steps, fitness),
                **judged_summary(
                    judged["env_steps"],
                    judged["fitness_all"],
                    judged["fitness_mean"],
                    [LABELS[i] for i in judged["label"]],
                ),
                "returned_fitness": result.fitness,
                "start_fitness": result.start_fitness,
                "env_steps": result.env_steps,
                "episodes": len(result.history),
                **rollout,
                "history_env_steps": steps,
                "history_greedy_fitness": fitness,
                "history_judged_env_steps": judged["env_steps"],
                "history_fitness_all": judged["fitness_all"],
                "history_fitness_mean": judged["fitness_mean"],
                "history_label": judged["label"],
            }
        )
    record = {
        "cell": cell.to_dict(),
        "name": cell.name,
        "settings": config.cell_settings(cell),
        "labels": list(LABELS),
        "seconds": trained_seconds + time.perf_counter() - start,
        "searches": searches,
    }
    return record, CellParameters(best_thetas, best_omegas)


def judged_summary(
    steps: list[int], fitness_all: list[float], fitness_mean: list[float], labels: list[str]
) -> dict[str, Any]:
    """When a search's optima got good, under both aggregations, from its judged policies
    (env steps at their episodes' ends, fitness under ``all`` and ``mean``, label).

    Under aggregation ``a`` the search's optimum changes whenever a judged policy scores
    strictly more under ``a`` than every earlier one. Per ``a``: ``best_<a>`` (0 if none was
    judged), ``first_090_<a>_steps`` (the first optimum scoring at least
    :data:`BALANCING_FITNESS`), ``first_balancing_<a>_steps`` (the first labelled
    ``balancing``) and ``first_rod_up_<a>_steps`` (the first with a rod balanced: labelled
    ``one rod up`` or ``balancing``, :data:`ROD_UP_LABELS`); None where none did.
    """
    out: dict[str, Any] = {}
    for name, fitness in zip(AGGREGATIONS, (fitness_all, fitness_mean), strict=True):
        best = -math.inf
        firsts: dict[str, int | None] = {"090": None, "balancing": None, "rod_up": None}
        for step, value, kind in zip(steps, fitness, labels, strict=True):
            if not value > best:
                continue
            best = value
            hits = {
                "090": value >= BALANCING_FITNESS,
                "balancing": kind == "balancing",
                "rod_up": kind in ROD_UP_LABELS,
            }
            for key, hit in hits.items():
                if hit and firsts[key] is None:
                    firsts[key] = int(step)
        out[f"best_{name}"] = max(best, 0.0)
        for key, value in firsts.items():
            out[f"first_{key}_{name}_steps"] = value
    return out


def history_summary(steps: list[int], fitness: list[float]) -> dict[str, Any]:
    """Best greedy fitness of a trained policy (0 if none was judged), the env steps of the
    first non-zero one and of the first at least :data:`BALANCING_FITNESS` (None if never),
    from a search's per-episode history. Episodes whose policy was not judged (before the
    first update, or between two multiples of ``judge_every``) carry no greedy fitness (NaN)
    and are skipped."""
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


def run_and_store_cell(
    out: str | Path,
    cell: Cell,
    config: CalibrationConfig,
    checkpoint_seconds: float = 600.0,
    progress: bool = False,
    check_steps: int = 1000,
) -> str:
    """Run one cell (continuing its in-flight checkpoint in ``out``, if any) and write it
    atomically: the best Actors and Critics first (``theta``, ``omega``), then the record;
    then remove its checkpoint."""
    record, (thetas, omegas) = run_cell(
        cell,
        config,
        out,
        checkpoint_seconds=checkpoint_seconds,
        progress=progress,
        check_steps=check_steps,
    )
    record_path, actors_path = cell_paths(Path(out), cell)

    buffer = io.BytesIO()
    np.savez_compressed(buffer, theta=thetas.astype(np.float32), omega=omegas.astype(np.float32))
    atomic_write(actors_path, buffer.getvalue())
    write_json(record_path, record, compact=True)  # ~15k episodes per search: ~1.3 MB, not 3.5
    CellCheckpoint(out, cell.name).remove()
    return cell.name


def read_cell(out: Path, cell: Cell, config: CalibrationConfig) -> dict[str, Any] | None:
    """A stored cell record, None if the cell has not finished. A record made with other
    settings (seeds, budget, base physics) raises ValueError naming the file."""
    path = cell_paths(out, cell)[0]
    if not path.exists():
        return None
    record = read_json(path)
    if record.get("settings") != json_roundtrip(config.cell_settings(cell)):
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


__all__ = [
    "CELL_COLUMNS",
    "DEFAULT_CELLS",
    "CalibrationConfig",
    "Cell",
    "CellParameters",
    "StartSpread",
    "greedy_rollout",
    "grid",
    "integrator_drift",
    "judged_summary",
    "load_calibration",
    "named_calibration",
    "run_cell",
    "with_overrides",
]
