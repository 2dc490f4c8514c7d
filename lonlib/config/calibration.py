"""A calibration study's configuration: the grid of physics cells (:class:`Cell`), where
exploring training episodes start (:class:`StartSpread`), the seeds and the DDPG budget
(:class:`CalibrationConfig`), validated when made; the named grids and YAML files. The study
itself: :mod:`lonlib.calibration.study`."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lonlib.config.ddpg import DDPGConfig, without_default_judging
from lonlib.config.pendulum import PendulumConfig
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
