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

The replay checks lie in the private module ``_verify_replay``, what they find
(:class:`Finding`, :class:`VerifyReport`) in ``_verify_report``; their names are imported from
here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lonlib.analysis._verify_replay import (
    TASK_REPLAY_TOLERANCE,
    algorithm_findings,
    check_recordings,
    check_starts,
    check_trial,
    stored_actors,
    task_replays_exactly,
    verify_task_trials,
)
from lonlib.analysis._verify_report import Finding, VerifyReport
from lonlib.analysis.recordings import recordings_index
from lonlib.storage.digests import (
    SealCheck,
    check_experiment_seal,
    figure_files,
    reseal_outputs,
    seal_runs,
    stale_figures,
)
from lonlib.storage.layout import MANIFEST_LOCK, read_manifest
from lonlib.storage.lock import exclusive_lock, sampling_lock_or_refuse
from lonlib.storage.result_path import KNOWN_RESULT_PATH_VERSIONS, RESULT_PATH_VERSION
from lonlib.task.behaviour import BehaviourDescriptor, describe_actors

__all__ = [
    "Finding",
    "TASK_REPLAY_TOLERANCE",
    "VerifyReport",
    "algorithm_findings",
    "blocks_sealing",
    "seal_experiment",
    "seal_findings",
    "session_versions",
    "task_replays_exactly",
    "verify_experiment",
]


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
        verify_task_trials(folder, config, trials, report, mismatch)
        if recordings:  # they show the trial's fitness; no descriptor to compare
            check_recordings(folder, trials, {}, report, mismatch)
        return report
    thetas, rows = stored_actors(folder, trials, config, report, mismatch)
    scoring = config.ddpg.scoring
    replayed: dict[tuple[float, int, int], BehaviourDescriptor] = {}
    for start in range(0, len(rows), batch):
        chunk = rows[start : start + batch]
        descriptors = describe_actors(np.stack(thetas[start : start + batch]), config.env, scoring)
        for row, descriptor in zip(chunk, descriptors, strict=True):
            report.findings.extend(check_trial(row, descriptor, scoring.estimate, mismatch))
            replayed[(float(row["p"]), int(row["run"]), int(row["index"]))] = descriptor
        report.replayed += len(chunk)
    check_starts(folder, config, trials, report, mismatch, batch)
    if recordings:
        check_recordings(folder, trials, replayed, report, mismatch)
    return report


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
