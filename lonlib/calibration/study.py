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
situation); the ``height-product`` reward is a :class:`lonlib.config.pendulum.PendulumConfig`
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
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from lonlib.calibration.inflight import CellCheckpoint
from lonlib.config import CalibrationConfig, Cell, PendulumConfig, Scoring
from lonlib.config.calibration import INTEGRATORS
from lonlib.ddpg.slots import LocalSearchResult
from lonlib.ddpg.trainer import SlotTrainer
from lonlib.storage.atomic import atomic_write, read_json, write_json
from lonlib.task.behaviour import LABELS, describe_actors, describe_rollout, label
from lonlib.task.pendulum import total_energy, wrap_angle
from lonlib.task.policy import actor_spec, critic_spec
from lonlib.task.rollout import Rollout, run_policy
from lonlib.util import portable_math
from lonlib.util.validation import (
    check_range,
)

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

    ``scoring`` gives the starts (:class:`lonlib.config.scoring.Scoring`, default ``Scoring()``);
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
    "CellParameters",
    "greedy_rollout",
    "integrator_drift",
    "judged_summary",
    "run_cell",
]
