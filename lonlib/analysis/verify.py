"""``lonlib verify``: every number stored for a local optimum replays from its stored Actor.

For every stored trial of an experiment this re-runs its Actor through the public API (the
one rollout, :func:`lonlib.task.behaviour.describe_actors`, with the experiment's scoring) and
checks, exactly (bit for bit, no tolerance):

* ``fitness``: the stored fitness is what the Actor scores (the nominal fitness, or the
  robust mean under ``fitness_estimate: robust``);
* ``descriptor``: the stored behaviour columns (``b_*``) are the replayed episode's, so they
  describe the scored episode, and the stored label is that descriptor's label;
* ``consistency``: ``b_fitness`` equals ``fitness`` (nominal estimate) and the end step can
  carry the fitness (``fitness_all <= end_step / steps``);
* ``start``: the stored ``start_fitness`` is what the search's start scores: the run's random
  initial Actor for its first search, else the stored parent optimum perturbed with the
  trial's own stream (:func:`lonlib.search.algorithm.search_start`), so the *improved on
  start* counts replay too;
* ``algorithm``: each run is Algorithm 2 under the manifest's settings: every trial's parent
  is the incumbent, it is accepted exactly when ``f >= f*`` (the first always), and no trial
  comes after the run's end (T consecutive failures or ``max_local_searches``), so a run
  sampled on under other settings is caught;
* ``recording``: every ``recordings/*.rrd`` names a stored trial (p, run, index) in its
  ``optimum`` property, carries that trial's fitness, and its Actor replays to it;
* ``digest``: every file matches the folder's seal (:mod:`lonlib.storage.digests`: each
  run's rows and files, chained; the recordings index; the figures), each that does not is
  named; an unsealed folder is a warning (``lonlib verify --seal`` seals it once it
  verifies).

Severity: on data of the current result-path version (:mod:`lonlib.storage.result_path`) every
mismatch is an error; on data sampled under another (or an unrecorded) version they are
warnings, reported with their counts, so an old experiment stays analysable while it is
replaced. A trial stored without its Actor (older experiments kept accepted optima only)
is a warning, "no Actor stored".
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from lonlib.analysis.recordings import recordings_index
from lonlib.search.algorithm import RunState, Trial, random_networks, search_start
from lonlib.storage.atomic import CorruptDataError
from lonlib.storage.digests import (
    SealCheck,
    check_experiment_seal,
    figure_files,
    reseal_outputs,
    seal_runs,
    stale_figures,
)
from lonlib.storage.layout import MANIFEST_LOCK, optimum_path, read_manifest
from lonlib.storage.lock import exclusive_lock, sampling_lock_or_refuse
from lonlib.storage.result_path import KNOWN_RESULT_PATH_VERSIONS, RESULT_PATH_VERSION
from lonlib.storage.trials import read_optimum
from lonlib.task.behaviour import PREFIX, BehaviourDescriptor, describe_actors, label
from lonlib.task.gymnasium_task import environment_versions
from lonlib.task.interface import task_of
from lonlib.task.policy import actor_spec, critic_spec
from lonlib.task.rollout import score_actors

__all__ = [
    "Finding",
    "VerifyReport",
    "blocks_sealing",
    "seal_experiment",
    "seal_findings",
    "verify_experiment",
]


@dataclass(frozen=True)
class Finding:
    """One check that did not hold (or could not run) for one trial or recording."""

    severity: str  # "error", "warning" or "info" (what applied, e.g. exact or tolerant replay)
    check: str  # fitness, descriptor, label, consistency, actor, recording, version
    p: float | None
    run: int | None
    index: int | None
    message: str

    def __str__(self) -> str:
        where = "" if self.p is None else f"p={self.p:g} run {self.run} index {self.index}: "
        return f"{self.severity}: [{self.check}] {where}{self.message}"


@dataclass
class VerifyReport:
    """What :func:`verify_experiment` found."""

    folder: Path
    trials: int = 0  # trials in the experiment
    replayed: int = 0  # trials whose Actor was stored and replayed
    starts: int = 0  # trials whose start was rebuilt and scored
    recordings: int = 0  # recordings checked
    current_version: bool = True  # every session ran the current result-path version
    sealed: bool = True  # the folder has a seal (lonlib.storage.digests)
    recordings_checked: bool = True  # the recordings were replayed and their index checked
    findings: list[Finding] = field(default_factory=list)

    @property
    def errors(self) -> list[Finding]:
        """Findings that fail the verification."""
        return [f for f in self.findings if f.severity == "error"]

    @property
    def warnings(self) -> list[Finding]:
        """Findings reported without failing it."""
        return [f for f in self.findings if f.severity == "warning"]

    @property
    def ok(self) -> bool:
        """True when no check failed (warnings allowed)."""
        return not self.errors

    def counts(self) -> Counter:
        """Findings by (severity, check)."""
        return Counter((f.severity, f.check) for f in self.findings)

    def summary(self) -> str:
        """A few lines for the terminal: what was checked and what did not hold."""
        lines = [
            f"{self.folder}: {self.trials} trials, {self.replayed} replayed from their stored "
            f"Actor, {self.starts} starts rebuilt and scored, {self.recordings} recordings"
        ]
        if not self.current_version:
            lines.append(
                f"sampled under another result-path version than this code's "
                f"({RESULT_PATH_VERSION}): mismatches are reported as warnings"
            )
        if not self.sealed:
            lines.append(f"unsealed: `lonlib verify {self.folder} --seal` seals it if it verifies")
        for (severity, check), count in sorted(self.counts().items()):
            lines.append(f"  {severity}s [{check}]: {count}")
        lines.append("verify: OK" if self.ok else f"verify: FAILED ({len(self.errors)} errors)")
        return "\n".join(lines)


NUMERIC_PACKAGES = ("python", "numpy", "torch")
"""The recorded versions a local search's numbers depend on (the provenance warning says
whether they agree when the installed sets differ)."""


def session_versions(folder: Path) -> list[str | None]:
    """The result-path version each session of an experiment recorded (None: unrecorded)."""
    sessions = read_manifest(folder).get("sessions", [])
    return [session.get("result_path_version") for session in sessions]


def _provenance_findings(folder: Path) -> list[Finding]:
    """Warnings for sessions that ran another environment (lock hash or installed set) or
    other torch CPU kernels than the others: training may then differ in the last bits."""
    manifest = read_manifest(folder)
    sessions = manifest.get("sessions", [])
    # the creating session's versions are the manifest's own
    versions = [
        s.get("versions") or (manifest.get("versions") if i == 0 else None)
        for i, s in enumerate(sessions)
    ]
    facts = {
        "environment (lock or installed packages)": [
            (s.get("environment") or {}).get("installed_sha256") for s in sessions
        ],
        "torch CPU kernels": [(s.get("cpu") or {}).get("torch") for s in sessions],
    }
    out = []
    environments = facts["environment (lock or installed packages)"]
    numeric = {  # per environment, the versions training depends on, where recorded
        environment: {
            tuple(v.get(name) for name in NUMERIC_PACKAGES)
            for v, e in zip(versions, environments, strict=True)
            if e == environment and v
        }
        for environment in set(environments) - {None}
    }
    numeric_agree = all(numeric.values()) and len(set().union(*numeric.values())) == 1
    for what, values in facts.items():
        recorded = [v for v in values if v is not None]
        if len(set(recorded)) > 1:
            same = what.startswith("environment") and numeric_agree
            consequence = (
                f"the packages training depends on ({', '.join(NUMERIC_PACKAGES)}) have the "
                "same versions in all of them, so only a change outside those could matter"
                if same
                else "their runs may differ from a single-session run in the last bits of training"
            )
            out.append(
                Finding(
                    "warning",
                    "provenance",
                    None,
                    None,
                    None,
                    f"sessions ran with {len(set(recorded))} different {what} "
                    f"({', '.join(sorted(str(v)[:12] for v in set(recorded)))}): {consequence}",
                )
            )
    return out


def verify_experiment(folder: str | Path, recordings: bool = True, batch: int = 32) -> VerifyReport:
    """Replay every stored trial (and recording) of the experiment in ``folder`` and report
    what does not come back exactly (see the module docstring)."""
    from lonlib.analysis.pipeline import load_experiment

    folder = Path(folder)
    config, trials = load_experiment(folder, check_seal=False)  # differences are findings
    versions = session_versions(folder)
    current = bool(versions) and all(v == RESULT_PATH_VERSION for v in versions)
    unknown = sorted({str(v) for v in versions if v is not None} - set(KNOWN_RESULT_PATH_VERSIONS))
    report = VerifyReport(folder, trials=len(trials), current_version=current or bool(unknown))
    mismatch = "error" if current or unknown else "warning"
    if unknown:
        report.findings.append(
            Finding(
                "error",
                "version",
                None,
                None,
                None,
                f"manifest.json: sessions ran result-path version(s) {unknown}, which this code "
                f"does not know (known: {list(KNOWN_RESULT_PATH_VERSIONS)}); every mismatch "
                "stays an error",
            )
        )
    elif not current:
        found = sorted({str(v) for v in versions})
        report.findings.append(
            Finding(
                "warning",
                "version",
                None,
                None,
                None,
                f"sessions ran result-path versions {found} ('None': not recorded); this code "
                f"is {RESULT_PATH_VERSION}",
            )
        )
    report.findings.extend(_provenance_findings(folder))
    seal = check_experiment_seal(folder, read_manifest(folder), recordings=recordings)
    report.sealed = seal.sealed
    report.recordings_checked = recordings
    report.findings.extend(seal_findings(seal))
    # Algorithm 2's bookkeeping does not depend on the result path: always an error
    report.findings.extend(algorithm_findings(config, trials))
    if config.task is not None:
        _verify_task_trials(folder, config, trials, report, mismatch)
        if recordings:  # they show the trial's fitness; no descriptor to compare
            _check_recordings(folder, trials, {}, report, mismatch)
        return report
    thetas, rows = _stored_actors(folder, trials, config, report, mismatch)
    scoring = config.ddpg.scoring
    replayed: dict[tuple[float, int, int], BehaviourDescriptor] = {}
    for start in range(0, len(rows), batch):
        chunk = rows[start : start + batch]
        descriptors = describe_actors(np.stack(thetas[start : start + batch]), config.env, scoring)
        for row, descriptor in zip(chunk, descriptors, strict=True):
            report.findings.extend(_check_trial(row, descriptor, scoring.estimate, mismatch))
            replayed[(float(row["p"]), int(row["run"]), int(row["index"]))] = descriptor
        report.replayed += len(chunk)
    _check_starts(folder, config, trials, report, mismatch, batch)
    if recordings:
        _check_recordings(folder, trials, replayed, report, mismatch)
    return report


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


def _verify_task_trials(folder: Path, config, trials: pd.DataFrame, report, mismatch) -> None:
    """A Gymnasium task's trials: every stored Actor's greedy episode replayed
    (:meth:`lonlib.task.gymnasium_task.GymnasiumTask.fitness`) and every start rebuilt; exact
    where :func:`task_replays_exactly`, else within :data:`TASK_REPLAY_TOLERANCE` (a
    difference beyond it is then a warning)."""
    task = task_of(config)
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

    thetas, rows = _stored_actors(
        folder, trials, config, report, mismatch, task.actor_spec.n_params
    )
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
        report.replayed += 1
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


def seal_findings(seal: SealCheck) -> list[Finding]:
    """The ``digest`` check: each file that differs from the folder's seal (an error naming
    it), each interrupted write the next run completes (a warning), an unsealed folder (a
    warning)."""
    if not seal.sealed:
        return [
            Finding(
                "warning",
                "digest",
                None,
                None,
                None,
                "unsealed (written before digests): nothing says whether a file changed since",
            )
        ]
    return [
        Finding("error", "digest", None, None, None, f"{name}: {what}")
        for name, what in seal.problems
    ] + [
        Finding("warning", "digest", None, None, None, f"{name}: {what}")
        for name, what in seal.pending
    ]


def seal_experiment(report: VerifyReport) -> None:
    """Seal the experiment ``report`` verified (``lonlib verify --seal``): every run's trials
    and files, the recordings index and the figures, as they are, each figure with the
    inputs it was drawn from (one drawn from an earlier state of the trials, or from trials
    no seal recorded, stays stale until ``lonlib analyse``); the manifest then records that
    the folder is sealed. ValueError when the verification failed: a folder is sealed only
    after a full replay holds."""
    # A seal interrupted part-way (runs sealed, the root not yet) is this command's own
    # state: sealing again completes it. Every other finding stops it.
    if blocks_sealing(report):
        raise ValueError(
            f"{report.folder}: verify failed or a stored number does not replay; only a folder "
            "that verifies and replays is sealed"
        )
    if not report.recordings_checked:
        raise ValueError("--seal seals the recordings too: run it without --no-recordings")
    folder = report.folder
    with sampling_lock_or_refuse(folder, "seal"):
        with exclusive_lock(folder / MANIFEST_LOCK, record_holder=False):
            stale = stale_figures(folder)  # before the runs' chains are sealed again
            seal_runs(folder, read_manifest(folder))
        reseal_outputs(
            folder,
            figures=figure_files(folder),
            recordings=recordings_index(folder),
            stale_figures=stale,
        )


REPLAY_CHECKS = ("fitness", "descriptor", "label", "consistency", "start", "recording")
"""The checks whose finding says a stored number does not replay: a warning of one of them
(data of another result-path version) still stops ``verify --seal``."""


def blocks_sealing(report: VerifyReport) -> bool:
    """Whether ``report`` has an error other than a missing root seal (this command's own
    interrupted seal, runs sealed and the root not yet, or a seal removed with the runs'
    digests to accept a deliberate change), which sealing after a full replay completes,
    or any replay mismatch, even one reported as a warning (data of another result-path
    version): a folder is sealed only when every stored number replays."""
    return any(not _interrupted_seal(finding) for finding in report.errors) or any(
        finding.check in REPLAY_CHECKS for finding in report.warnings
    )


def _interrupted_seal(finding: Finding) -> bool:
    return finding.check == "digest" and finding.message.startswith("seal.json: missing, while")


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


def _stored_actors(
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


def _check_trial(
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


def _check_starts(folder: Path, config, trials: pd.DataFrame, report, mismatch, batch) -> None:
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


def _check_recordings(folder, trials, replayed, report, mismatch) -> None:
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
