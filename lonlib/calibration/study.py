"""Calibration study: which physics lets DDPG leave the zero-fitness plateau, and how. This
module runs one cell of it: its searches' starts, their training and their description.

A study is a grid of **cells**; a cell fixes the motor model (force, acceleration or
velocity), its gain or time constant, the integrator and the DDPG reward. For every cell,
``seeds`` agents train with lonlib's batched DDPG (one :class:`lonlib.ddpg.trainer.SlotTrainer`
per cell, :func:`run_cell`) for exactly ``max_steps`` environment steps each (no early stop, so
cells compare at equal budget). Seed ``i`` starts from the same Actor and Critic and draws the
same random streams in every cell (common random numbers, :func:`seed_streams`), so cells
differ only by their physics.

Per search the study reads the training history (greedy fitness after every episode) and
replays the returned Actor greedily once; per cell it reports

* the share of searches **leaving zero** (best greedy fitness of a trained policy > 0),
* the **env steps to the first non-zero** greedy fitness,
* the **best fitness** (:func:`lonlib.calibration.summaries.history_summary`), and
* **what the best policies do** in their greedy rollout
  (:func:`lonlib.calibration.greedy.greedy_rollout`, the behaviour descriptor of
  :mod:`lonlib.task.behaviour`): upright share and signed full turns per rod, end reason and
  step, the carts' mean range, the fitness from perturbed starts, and the behaviour label
  (one of :data:`lonlib.task.behaviour.LABELS`).

Beside the grid, :func:`lonlib.calibration.drift.integrator_drift` measures each integrator's
energy and momentum drift in a short motor-off, friction-off rollout. Every episode here runs
through the one rollout (:func:`lonlib.task.rollout.run_policy`).

:func:`lonlib.calibration.campaign.run_calibration` runs the cells in a process pool (one torch
thread per worker; each cell :func:`run_and_store_cell`) and writes each finished cell
atomically to ``<out>/cells/<cell>.json`` (its Actors to ``<cell>.npz``;
:mod:`lonlib.calibration.cell_store`): a killed study resumes with the cells it has not
finished. It then writes its report (:mod:`lonlib.calibration.report`): ``calibration.csv``
(one row per cell), ``searches.csv`` (one row per search), ``drift.csv``, ``calibration.md``
and ``calibration.png``.

**Learner-side cells** (the two-cart study, ``configs/study-two-cart.yaml``): a cell may
also set ``exploring_starts`` (training episodes start from
:class:`StartSpread`, the greedy evaluations keep Algorithm 1's start) and ``continue_from``
(its searches start from the best Actor and Critic that search ``i`` of an earlier cell
stored, with fresh replay buffers, Adam state and random streams: a basin-hopping chain's
situation; :func:`cell_starts`); the ``height-product`` reward is a
:class:`lonlib.config.pendulum.PendulumConfig` reward. Every judged policy of a search is
also described (:class:`lonlib.calibration.judged_log.JudgedLog`,
:func:`lonlib.calibration.summaries.judged_summary`): its nominal episode's fitness under both
aggregations and its behaviour label. A cell's searches train with in-flight checkpoints
(:mod:`lonlib.calibration.inflight`): a killed study resumes mid-cell and gives the same
cells as an uninterrupted one.

The names this module listed before the study was split by job (:data:`CELL_COLUMNS`,
:func:`greedy_rollout`, :func:`integrator_drift`, :func:`judged_summary`) are re-exported here.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from lonlib.calibration.cell_store import cell_paths, read_arrays, read_cell, write_cell
from lonlib.calibration.greedy import greedy_rollout
from lonlib.calibration.inflight import CellCheckpoint
from lonlib.calibration.judged_log import JudgedLog
from lonlib.calibration.summaries import history_summary, judged_summary
from lonlib.config import CalibrationConfig, Cell
from lonlib.ddpg.slots import LocalSearchResult
from lonlib.ddpg.trainer import SlotTrainer
from lonlib.task.behaviour import LABELS
from lonlib.task.policy import actor_spec, critic_spec
from lonlib.util.validation import (
    check_range,
)

PROGRESS_SECONDS = 300.0  # at most one progress line per cell this often


# ---------------------------------------------------------------------------- the starts
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
    arrays = read_arrays(Path(out), source)
    if "omega" not in arrays:
        raise ValueError(
            f"continue_from: {path} holds no Critics (stored before the study kept them); "
            f"recompute the cell {source.name!r}"
        )
    thetas, omegas = arrays["theta"], arrays["omega"]
    if len(thetas) != config.seeds:
        raise ValueError(f"continue_from: {path} holds {len(thetas)} searches, not {config.seeds}")
    return thetas, omegas, [continue_seed(config, i) for i in range(config.seeds)]


# ---------------------------------------------------------------------------- one cell
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
    finished = [r for r in results if r is not None]
    if len(finished) != config.seeds:
        raise RuntimeError(f"{cell.name}: {config.seeds - len(finished)} searches returned nothing")
    best_thetas = np.stack([r.theta for r in finished])
    best_omegas = np.stack([r.omega for r in finished])
    rollouts = greedy_rollout(best_thetas, env, hp.scoring)
    searches = []
    for index, (result, rollout) in enumerate(
        zip(finished, rollouts.to_dict("records"), strict=True)
    ):
        history_steps = [h.env_steps for h in result.history]
        fitness = [h.greedy_fitness for h in result.history]
        judged = log.rows[index]
        searches.append(
            {
                "seed_index": index,
                **history_summary(history_steps, fitness),
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
                "history_env_steps": history_steps,
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


def run_and_store_cell(
    out: str | Path,
    cell: Cell,
    config: CalibrationConfig,
    checkpoint_seconds: float = 600.0,
    progress: bool = False,
    check_steps: int = 1000,
) -> str:
    """Run one cell (continuing its in-flight checkpoint in ``out``, if any) and write it
    atomically (:func:`lonlib.calibration.cell_store.write_cell`: the best Actors and Critics
    first, then the record); then remove its checkpoint."""
    record, (thetas, omegas) = run_cell(
        cell,
        config,
        out,
        checkpoint_seconds=checkpoint_seconds,
        progress=progress,
        check_steps=check_steps,
    )
    write_cell(out, cell, record, thetas, omegas)
    CellCheckpoint(out, cell.name).remove()
    return cell.name


__all__ = [
    "CellParameters",
    "cell_starts",
    "continue_seed",
    "run_and_store_cell",
    "run_cell",
    "seed_streams",
]
