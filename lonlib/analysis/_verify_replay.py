"""The replay checks of ``lonlib verify`` (:mod:`lonlib.analysis.verify`): each stored
Actor's fitness and behaviour, each search's start, each run's Algorithm 2 bookkeeping, each
recording, and a Gymnasium task's trials; exact comparisons (NaN equal to NaN)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from lonlib.analysis._verify_report import Finding, VerifyReport
from lonlib.search.algorithm import RunState, Trial, random_networks, search_start
from lonlib.storage.atomic import CorruptDataError
from lonlib.storage.layout import optimum_path, read_manifest
from lonlib.storage.trials import read_optimum
from lonlib.task.behaviour import PREFIX, BehaviourDescriptor, label
from lonlib.task.gymnasium_behaviour import describe_optimum
from lonlib.task.gymnasium_task import environment_versions
from lonlib.task.interface import task_of
from lonlib.task.policy import actor_spec, critic_spec
from lonlib.task.rollout import score_actors

TASK_REPLAY_TOLERANCE = 1e-9
"""How far a Gymnasium task's replayed fitness may be from the stored one where the replay
need not be exact (another CPU capability or Gymnasium version than the sampling's): the
environment's own float arithmetic is not lonlib's to define, and a chaotic episode may move
further (then a warning, not an error)."""


def task_replays_exactly(folder: Path, config) -> bool:
    """Must a Gymnasium task's greedy episodes replay bit for bit here? Yes when every
    session recorded this machine's numpy CPU dispatch and this environment's source and
    versions (:func:`lonlib.task.gymnasium_task.environment_versions`; sessions from before
    it was recorded: the manifest's Gymnasium version)."""
    import gymnasium

    from lonlib.util.cpu_kernels import cpu_record

    manifest = read_manifest(folder)
    sessions = manifest.get("sessions", [])
    here = cpu_record(None).get("numpy")
    same_cpu = all((s.get("cpu") or {}).get("numpy") == here for s in sessions)
    source = environment_versions(config.task)
    same_source = all(
        s.get("task_environment", {"gymnasium": (manifest.get("versions") or {}).get("gymnasium")})
        in (source, {"gymnasium": gymnasium.__version__})
        for s in sessions
    )
    return same_cpu and same_source


def verify_task_trials(folder: Path, config, trials: pd.DataFrame, report, mismatch) -> None:
    """A Gymnasium task's trials: every stored Actor's greedy episode replayed
    (:meth:`lonlib.task.gymnasium_task.GymnasiumTask.fitness`) and every start rebuilt; exact
    where :func:`task_replays_exactly`, else within :data:`TASK_REPLAY_TOLERANCE` (a
    difference beyond it is then a warning). A descriptor whose module does not import here
    is one warning naming it (the report then says the verification is incomplete), and
    every fitness is replayed all the same."""
    config, task = _replayable_task(config, report)
    exact = task_replays_exactly(folder, config)
    severity = mismatch if exact else "warning"
    report.findings.append(
        Finding(
            "info",
            "task",
            None,
            None,
            None,
            f"{task.name}: "
            + (
                "same CPU dispatch and Gymnasium version as the sampling: replayed bit for bit"
                if exact
                else "another CPU dispatch or Gymnasium version than the sampling: replayed "
                f"within {TASK_REPLAY_TOLERANCE:g} (larger differences are warnings)"
            ),
        )
    )

    def differs(stored: float, replayed: float) -> bool:
        if exact:
            return not _same(stored, replayed)
        return not (_number(stored) and abs(float(stored) - replayed) <= TASK_REPLAY_TOLERANCE)

    def behaviour_differs(stored: float, replayed: float) -> bool:
        """A ``b_*`` value is on the descriptor's own scale: relative and absolute tolerance."""
        if exact:
            return not _same(stored, replayed)
        tolerance = TASK_REPLAY_TOLERANCE
        return not (
            _number(stored)
            and math.isclose(float(stored), replayed, rel_tol=tolerance, abs_tol=tolerance)
        )

    thetas, rows = stored_actors(folder, trials, config, report, mismatch, task.actor_spec.n_params)
    for row, theta in zip(rows, thetas, strict=True):
        replayed = float(task.fitness(theta[None])[0])
        if differs(row["fitness"], replayed):
            report.findings.append(
                Finding(
                    severity,
                    "fitness",
                    float(row["p"]),
                    int(row["run"]),
                    int(row["index"]),
                    f"stored {row['fitness']!r}, its Actor scores {replayed!r}",
                )
            )
        if task.config.descriptor:
            report.findings.extend(
                _check_task_descriptor(task, row, theta, severity, behaviour_differs)
            )
        report.replayed += 1
    if task.config.descriptor:
        report.findings.append(
            Finding(
                "info",
                "descriptor",
                None,
                None,
                None,
                f"{task.config.descriptor}: every stored behaviour replayed from its Actor",
            )
        )
    elif report.descriptor_checked:
        report.findings.extend(_undescribed_behaviour(rows, mismatch))
    for row, start in _rebuilt_starts(folder, config, trials, task.actor_spec.n_params):
        replayed = float(task.fitness(start[None])[0])
        if differs(row["start_fitness"], replayed):
            report.findings.append(
                Finding(
                    severity,
                    "start",
                    float(row["p"]),
                    int(row["run"]),
                    int(row["index"]),
                    f"stored start fitness {row['start_fitness']!r}, the rebuilt start "
                    f"(parent {int(row['parent'])}) scores {replayed!r}",
                )
            )
        report.starts += 1


def _replayable_task(config: Any, report: VerifyReport) -> tuple[Any, Any]:
    """The configuration and task whose trials are replayed: ``config``'s, or, when its
    descriptor's module does not import here, the same without the descriptor, with a
    warning naming it (the stored behaviour is then not replayed, and the report is
    incomplete)."""
    try:
        return config, task_of(config)
    except ValueError as error:
        if not (config.task.descriptor and str(error).startswith("task.descriptor")):
            raise
        unimported = str(error)
    report.descriptor_checked = False
    report.findings.append(
        Finding(
            "warning",
            "descriptor",
            None,
            None,
            None,
            f"{unimported}: the stored behaviour (b_*, label) is not replayed; every fitness is. "
            "Install that module (or put it on PYTHONPATH) and verify again",
        )
    )
    bare = dataclasses.replace(config, task=dataclasses.replace(config.task, descriptor=""))
    return bare, task_of(bare)


def _undescribed_behaviour(rows: list[dict], severity: str) -> list[Finding]:
    """Behaviour (``b_*``, ``label``) stored for trials of a task whose configuration names
    no descriptor: nothing can replay it (one finding)."""
    stored = sorted(
        {
            name
            for row in rows
            for name, value in row.items()
            if (name.startswith(PREFIX) or name == "label")
            and (isinstance(value, str) or _number(value))
        }
    )
    if not stored:
        return []
    return [
        Finding(
            severity,
            "descriptor",
            None,
            None,
            None,
            f"{', '.join(stored)} stored but not replayed: the configuration names no "
            "task.descriptor",
        )
    ]


def _check_task_descriptor(
    task: Any, row: dict, theta: np.ndarray, severity: str, differs: Callable[[Any, float], bool]
) -> Iterable[Finding]:
    """A stored Gymnasium optimum's ``b_*`` columns and label against its Actor's replayed
    descriptor (:func:`lonlib.task.gymnasium_behaviour.describe_optimum`)."""
    p, run, index = float(row["p"]), int(row["run"]), int(row["index"])
    replayed = describe_optimum(task, theta, f"verify p={p:g} run {run} optimum {index}")
    stored = {
        k: v
        for k, v in row.items()
        if (k.startswith(PREFIX) or k == "label") and (isinstance(v, str) or _number(v))
    }
    if not stored:
        yield Finding(severity, "descriptor", p, run, index, "no behaviour descriptor stored")
        return
    differing = [
        f"{name} stored {stored.get(name)!r}, replayed {value!r}"
        for name, value in replayed.items()
        if (stored.get(name) != value if name == "label" else differs(stored.get(name), value))
    ]
    differing += [f"{name} stored but not replayed" for name in set(stored) - set(replayed)]
    if differing:
        yield Finding(severity, "descriptor", p, run, index, "; ".join(sorted(differing)))


def algorithm_findings(config, trials: pd.DataFrame, severity: str = "error") -> list[Finding]:
    """The ``algorithm`` check: where the stored runs of ``trials`` are not Algorithm 2's
    bookkeeping under ``config``'s basin-hopping settings (parents, acceptance by
    ``f >= f*``, the run's end)."""
    findings = []
    ordered = trials.sort_values(["p", "run", "index"])
    for (p, run), table in ordered.groupby(["p", "run"], sort=False):
        settings = config.basin_hopping(float(p))
        state = RunState(trials=[], incumbent=None, incumbent_index=-1, failures=0)
        best = None
        for row in table.to_dict("records"):
            where = (float(p), int(run), int(row["index"]))
            if state.finished:
                findings.append(
                    Finding(
                        severity,
                        "algorithm",
                        *where,
                        f"stored after the run ended ({state.end_reason}: T = "
                        f"{settings.tolerance}, max_local_searches = "
                        f"{settings.max_local_searches})",
                    )
                )
                break
            accepted, fitness = bool(row["accepted"]), float(row["fitness"])
            if int(row["parent"]) != state.incumbent_index:
                findings.append(
                    Finding(
                        severity,
                        "algorithm",
                        *where,
                        f"parent {row['parent']} is not the incumbent {state.incumbent_index}",
                    )
                )
            if accepted != (best is None or fitness >= best):
                findings.append(
                    Finding(
                        severity,
                        "algorithm",
                        *where,
                        f"accepted={accepted} but f = {fitness!r} against f* = {best!r}",
                    )
                )
            best = fitness if accepted else best
            trial = Trial(where[2], int(row["parent"]), fitness, accepted, 0.0, 0)
            state.record(trial, None, settings)
    return findings


def stored_actors(
    folder: Path,
    trials: pd.DataFrame,
    config,
    report: VerifyReport,
    mismatch: str,
    size: int | None = None,
) -> tuple[list[np.ndarray], list[dict]]:
    """The stored Actors that can be replayed; a missing or unusable file is a finding
    naming it (an error on data of this result-path version, where every trial's Actor is
    stored; a warning on older data, which kept accepted optima only). ``size``: the
    Actor's parameter count (default: the pendulums' of ``config.env``)."""
    size = actor_spec(config.env.n_carts).n_params if size is None else size
    thetas, rows = [], []
    for row in trials.to_dict("records"):
        p, run, index = float(row["p"]), int(row["run"]), int(row["index"])
        path = optimum_path(folder, p, run, index)
        if not path.exists():
            report.findings.append(Finding(mismatch, "actor", p, run, index, "no Actor stored"))
            continue
        try:
            theta = np.asarray(read_optimum(path).theta)
        except CorruptDataError as error:
            report.findings.append(Finding("error", "actor", p, run, index, str(error)))
            continue
        if theta.shape != (size,) or not np.isfinite(theta).all():
            problem = "NaN or infinite values" if theta.shape == (size,) else f"shape {theta.shape}"
            report.findings.append(
                Finding(
                    "error",
                    "actor",
                    p,
                    run,
                    index,
                    f"{path}: the Actor has {problem}, not {size} finite parameters",
                )
            )
            continue
        thetas.append(theta)
        rows.append(row)
    return thetas, rows


def check_trial(
    row: dict, replayed: BehaviourDescriptor, estimate: str, severity: str
) -> Iterable[Finding]:
    p, run, index = float(row["p"]), int(row["run"]), int(row["index"])
    expected = replayed.robust_mean if estimate == "robust" else replayed.fitness
    if not _same(row["fitness"], expected):
        yield Finding(
            severity,
            "fitness",
            p,
            run,
            index,
            f"stored {row['fitness']!r}, its Actor scores {expected!r}",
        )
    stored_columns = {k: v for k, v in row.items() if k.startswith(PREFIX)}
    if not stored_columns:
        yield Finding(severity, "descriptor", p, run, index, "no behaviour descriptor stored")
        return
    differing = [
        f"{name} stored {stored_columns.get(name)!r}, replayed {value!r}"
        for name, value in replayed.to_columns().items()
        if not _same(stored_columns.get(name), value)
    ]
    if differing:
        shown = "; ".join(differing[:3]) + (
            f"; +{len(differing) - 3} more" if len(differing) > 3 else ""
        )
        yield Finding(severity, "descriptor", p, run, index, shown)
    if row.get("label") != label(replayed):
        yield Finding(
            severity,
            "label",
            p,
            run,
            index,
            f"stored {row.get('label')!r}, the scored episode is {label(replayed)!r}",
        )
    if estimate == "nominal" and not _same(row.get(f"{PREFIX}fitness"), row["fitness"]):
        yield Finding(
            severity,
            "consistency",
            p,
            run,
            index,
            f"b_fitness {row.get(f'{PREFIX}fitness')!r} differs from fitness {row['fitness']!r}",
        )
    end_step, steps = row.get(f"{PREFIX}end_step"), row.get(f"{PREFIX}nominal_steps")
    possible = not (_number(end_step) and _number(steps)) or (
        row["fitness"] <= end_step / steps + 1e-12
    )
    if estimate == "nominal" and not possible:
        yield Finding(
            severity,
            "consistency",
            p,
            run,
            index,
            f"fitness {row['fitness']:.4f} cannot come from an episode that ended at step "
            f"{int(end_step)} of {int(steps)}",
        )


def check_starts(folder: Path, config, trials: pd.DataFrame, report, mismatch, batch) -> None:
    """Rebuild every search's start (the run's random Actor, or the stored parent optimum
    perturbed with the trial's stream) and check its score is the stored ``start_fitness``.
    A trial whose parent optimum is not stored, or that stored no start fitness (older
    data), is skipped."""
    rebuilt = _rebuilt_starts(folder, config, trials, actor_spec(config.env.n_carts).n_params)
    rows = [row for row, _ in rebuilt]
    starts = [theta for _, theta in rebuilt]
    scoring = config.ddpg.scoring
    for first in range(0, len(rows), batch):
        scores = score_actors(np.stack(starts[first : first + batch]), config.env, scoring)
        for row, score in zip(rows[first : first + batch], scores.fitness, strict=True):
            if not _same(row["start_fitness"], score):
                report.findings.append(
                    Finding(
                        mismatch,
                        "start",
                        float(row["p"]),
                        int(row["run"]),
                        int(row["index"]),
                        f"stored start fitness {row['start_fitness']!r}, the rebuilt start "
                        f"(parent {int(row['parent'])}) scores {float(score)!r}",
                    )
                )
        report.starts += len(rows[first : first + batch])


def _rebuilt_starts(
    folder: Path, config, trials: pd.DataFrame, size: int
) -> list[tuple[dict, np.ndarray]]:
    """``(trial row, start Actor)`` of every trial whose start can be rebuilt: the run's
    random Actor, or the stored parent optimum perturbed with the trial's stream. A trial
    whose parent optimum is not stored or unusable, or that stored no start fitness (older
    data), is left out."""
    if "start_fitness" not in trials.columns:
        return []
    if config.task is None:
        specs = (actor_spec(config.env.n_carts), critic_spec(config.env.n_carts), 1)
    else:
        task = task_of(config)
        specs = (task.actor_spec, task.critic_spec, task.critic_count)
    parents: dict[tuple[float, int, int], tuple[np.ndarray, np.ndarray] | None] = {}

    def parent_parameters(p: float, run: int, parent: int):
        """The stored parent's Actor and Critic, read once for all its children (None if
        missing or damaged: the actor check names it)."""
        key = (p, run, parent)
        if key not in parents:
            try:
                stored = read_optimum(optimum_path(folder, p, run, parent))
                parents[key] = (np.asarray(stored.theta), np.asarray(stored.omega))
            except (OSError, CorruptDataError):
                parents[key] = None
        return parents[key]

    out: list[tuple[dict, np.ndarray]] = []
    for row in trials.to_dict("records"):
        if not _number(row["start_fitness"]):
            continue
        p, run, parent = float(row["p"]), int(row["run"]), int(row["parent"])
        run_seed = config.run_seed(p, run)
        if parent >= 0:
            incumbent, initial = parent_parameters(p, run, parent), None
            if incumbent is None:
                continue
        else:
            incumbent, initial = None, random_networks(run_seed, *specs)
        theta = search_start(run_seed, int(row["index"]), p, incumbent, initial)[0]
        if theta.shape != (size,) or not np.isfinite(theta).all():
            continue  # the parent is unusable: the actor check names it
        out.append((row, theta))
    return out


def check_recordings(folder, trials, replayed, report, mismatch) -> None:
    """Each recording names a stored trial and shows its nominal episode: the recording's
    fitness, end reason and end step equal the trial's stored nominal fitness and those of
    its Actor's replayed episode."""
    from lonlib.analysis.recordings import recording_properties

    by_key = {(float(r.p), int(r.run), int(r.index)): r for r in trials.itertuples()}
    for path in sorted((folder / "recordings").glob("*.rrd")):
        report.recordings += 1
        try:
            props = recording_properties(path)
        except Exception as error:  # a damaged file is a finding, not a crash
            report.findings.append(
                Finding(
                    mismatch, "recording", None, None, None, f"{path.name}: unreadable ({error})"
                )
            )
            continue
        key = props.get("p"), props.get("run"), props.get("index")
        if None in key:
            report.findings.append(
                Finding(
                    mismatch,
                    "recording",
                    None,
                    None,
                    None,
                    f"{path.name}: names no trial (recorded before recordings carried p, run "
                    "and index); `lonlib record` records it again",
                )
            )
            continue
        key = (float(key[0]), int(key[1]), int(key[2]))
        trial = by_key.get(key)
        if trial is None:
            report.findings.append(
                Finding(mismatch, "recording", *key, f"{path.name}: no such stored trial")
            )
            continue
        stored = getattr(trial, f"{PREFIX}fitness", trial.fitness)
        shown = {k: props.get(k) for k in ("fitness", "end_reason", "end_step")}
        expected = {"fitness": stored}
        descriptor = replayed.get(key)
        if descriptor is not None:
            expected.update(end_reason=descriptor.end_reason, end_step=descriptor.end_step)
        differing = [
            f"{name} {shown[name]!r}, the trial's {value!r}"
            for name, value in expected.items()
            if not _same(shown[name], value)
        ]
        if differing:
            report.findings.append(
                Finding(
                    mismatch,
                    "recording",
                    *key,
                    f"{path.name} shows another episode: {'; '.join(differing)}",
                )
            )


def _number(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and math.isfinite(value)


def _same(stored, replayed) -> bool:
    """Exact equality, NaN equal to NaN (a one-rod phase), numbers compared as floats."""
    if isinstance(stored, str) or isinstance(replayed, str):
        return stored == replayed
    if stored is None or replayed is None:
        return stored is replayed
    stored, replayed = float(stored), float(replayed)
    return stored == replayed or (math.isnan(stored) and math.isnan(replayed))


__all__ = [
    "TASK_REPLAY_TOLERANCE",
    "algorithm_findings",
    "check_recordings",
    "check_starts",
    "check_trial",
    "stored_actors",
    "task_replays_exactly",
    "verify_task_trials",
]
