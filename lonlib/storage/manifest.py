"""The experiment manifest: what ``data/<experiment>/manifest.json`` records and checks.

It holds the configuration (merged over every session that added runs or p values), the
lonlib version, the git commit, package versions, the host and one entry per session. A
folder holding an experiment with a different configuration is refused.

Each session also records where its results came from (:func:`lonlib.storage.provenance.
session_provenance`): the lock's hash, the CPU kernels (numpy's dispatch targets, torch's
CPU capability) and the result-path version (:mod:`lonlib.storage.result_path`).
:func:`sessions_with_other_result_path` lists the sessions whose numbers came from another
result path; :func:`capability_change` says when a session computes with other torch CPU
kernels than the sessions before it.

A session that samples records its end (:func:`mark_session_ended`: ``ended`` and its wall
``seconds``) when the call returns or raises; a killed process records none.
:func:`session_seconds` sums them: the measured time of an experiment sampled across
sessions (sessions that ran at the same time each count).
"""

from __future__ import annotations

import dataclasses
import math
import platform
import subprocess
import uuid
from collections.abc import Collection, Mapping
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any

from lonlib.storage.atomic import read_json, write_json
from lonlib.storage.layout import checked_manifest, config_of_manifest
from lonlib.storage.result_path import RESULT_PATH_VERSION
from lonlib.storage.trials import runs_ending_early
from lonlib.task.gymnasium_task import environment_versions

if TYPE_CHECKING:
    from lonlib.config import ExperimentConfig

CHANGEABLE_FIELDS = ("max_local_searches",)
"""Settings a stored experiment may change when asked (``allow_changes``): a run's local
searches do not depend on them, only where the run ends."""

PACKAGES = (
    "numpy",
    "torch",
    "gymnasium",
    "stable-baselines3",  # the SB3 local searches (task.search: sb3-*), None when not installed
    "pandas",
    "pyarrow",
    "networkx",
    "igraph",
    "dask",
)


def manifest_path(out: Path) -> Path:
    """The manifest of the experiment folder ``out``."""
    return Path(out) / "manifest.json"


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


def updated_manifest(
    config: ExperimentConfig,
    out: Path,
    provenance: Mapping[str, Any] | None = None,
    allow_changes: Collection[str] = (),
) -> dict[str, Any]:
    """The manifest ``out`` should hold for ``config`` (new, or the stored one with this
    session added); refuses a folder holding another experiment. The new session records
    ``provenance`` (:func:`lonlib.storage.provenance.session_provenance`). Writes nothing.

    ``allow_changes`` names settings of :data:`CHANGEABLE_FIELDS` that may differ from the
    stored configuration: the change is accepted when every stored run is a valid start of a
    run under the new settings (:func:`lonlib.storage.trials.runs_ending_early`; a lowered
    ``max_local_searches`` ends the runs that reach it, a raised one continues the runs the
    old one ended) and is recorded in the session (``changed``: field, stored value, new)."""
    if isinstance(allow_changes, str) or not isinstance(allow_changes, Collection):
        raise ValueError(
            f"allow_changes must be a list of field names, e.g. ['max_local_searches'], "
            f"got {allow_changes!r}"
        )
    unknown = sorted(set(allow_changes) - set(CHANGEABLE_FIELDS))
    if unknown:
        raise ValueError(f"allow_changes must name fields of {CHANGEABLE_FIELDS}, got {unknown}")
    path = manifest_path(out)
    now = datetime.now(UTC).isoformat(timespec="seconds")
    if path.exists():
        manifest = checked_manifest(read_json(path), path)
        stored = config_of_manifest(manifest, path)
        changed = _changed_fields(stored, config)
        refused = [key for key in changed if key not in allow_changes]
        if refused:
            hint = (
                "; "
                + ", ".join(refused)
                + " may change where every stored run stays valid: lonlib run "
                + " ".join(f"--allow-change {key}" for key in refused)
                + " (allow_changes in Python)"
                if set(refused) <= set(CHANGEABLE_FIELDS)
                else ""
            )
            raise ValueError(
                f"{out} holds an experiment with a different configuration ({refused} differ); "
                f"choose another output folder or use the stored configuration{hint}"
            )
        record = {key: [getattr(stored, key), getattr(config, key)] for key in changed}
        _check_stored_runs_allow(out, stored, config, changed)
        if changed:
            stored = dataclasses.replace(stored, **{key: getattr(config, key) for key in changed})
        runs = max(stored.runs, config.runs)
        perturbations = tuple(dict.fromkeys((*stored.perturbations, *config.perturbations)))
        merged = dataclasses.replace(stored, runs=runs, perturbations=perturbations)
        manifest["config"] = merged.to_dict()
        manifest.setdefault("sessions", []).append(
            {
                "started": now,
                "id": uuid.uuid4().hex,
                "versions": _versions(),
                "git_commit": _git_commit(),
                **_task_environment(config),
                **({"changed": record} if record else {}),
                # where DDPG ran this session: not configuration (results do not depend on it)
                "execution": {
                    "device": config.ddpg.device,
                    "threads": config.ddpg.threads,
                    "executor": config.executor,
                    "slots": config.slots,
                },
                **(provenance or {}),
            }
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
            "sessions": [
                {
                    "started": now,
                    "id": uuid.uuid4().hex,
                    **_task_environment(config),
                    **(provenance or {}),
                }
            ],
        }
    return manifest


def _task_environment(config: ExperimentConfig) -> dict[str, Any]:
    """A Gymnasium task's environment source and versions, for the session (none for the
    coupled pendulums: their manifests stay as they were)."""
    if config.task is None:
        return {}
    return {"task_environment": environment_versions(config.task)}


def _changed_fields(stored: ExperimentConfig, config: ExperimentConfig) -> list[str]:
    """The result-changing settings (:meth:`ExperimentConfig.comparable`) that differ."""
    old, new = stored.comparable(), config.comparable()
    return sorted(key for key in new if old[key] != new[key])


def _check_stored_runs_allow(
    out: Path, stored: ExperimentConfig, config: ExperimentConfig, changed: list[str]
) -> None:
    """ValueError, naming the runs (and the changed fields), if a stored run of ``out`` would
    have ended before its last stored local search under ``config``'s basin-hopping
    settings: with no change, stored runs that went past where the recorded settings end
    them (sampled by a session under other settings) are refused too."""
    early = runs_ending_early(out, config.basin_hopping)
    listed = f"{'; '.join(early[:5])}{'; ...' if len(early) > 5 else ''}"
    if early and not changed:
        raise ValueError(
            f"{out}: {len(early)} stored run(s) go on past where Algorithm 2 under the stored "
            f"settings ends them (T = {config.tolerance}, max_local_searches = "
            f"{config.max_local_searches}): {listed}; they were sampled under other settings"
        )
    if early:
        what = ", ".join(
            f"{key} {getattr(stored, key)} -> {getattr(config, key)}" for key in changed
        )
        raise ValueError(
            f"{out}: cannot change {what}: {len(early)} stored run(s) would have ended before "
            f"their last stored local search ({listed}); max_local_searches must be at least every "
            "stored run's count"
        )


def mark_session_ended(out: Path, session_id: str, seconds: float) -> bool:
    """Record in ``out``'s manifest that the session ``session_id`` (its ``id``) ended now,
    after ``seconds`` of wall time. The caller holds the manifest lock. Returns False, writing
    nothing, when no session of the manifest has that id (or its sessions are not a list)."""
    path = manifest_path(out)
    manifest = checked_manifest(read_json(path), path)
    sessions = manifest.get("sessions")
    for session in sessions if isinstance(sessions, list) else []:
        if isinstance(session, dict) and session.get("id") == session_id:
            session["ended"] = datetime.now(UTC).isoformat(timespec="seconds")
            session["seconds"] = round(float(seconds), 1)
            write_json(path, manifest)
            return True
    return False


def _recorded_seconds(session: object) -> float | None:
    """A session's recorded wall seconds: a finite number >= 0 (not a bool), else None."""
    seconds = session.get("seconds") if isinstance(session, dict) else None
    if isinstance(seconds, bool) or not isinstance(seconds, int | float):
        return None
    try:
        value = float(seconds)
    except OverflowError:  # an int too large for a float
        return None
    return value if math.isfinite(value) and value >= 0 else None


def session_seconds(experiment: str | Path | Mapping[str, Any]) -> tuple[float, int, int]:
    """The sessions of ``experiment`` (a folder or its manifest): the wall seconds they
    recorded, summed (sessions that ran at the same time each count), how many sessions
    there are, and how many of them recorded no end (running, killed, stopped by a failed
    write, or sampled before lonlib recorded ends). Sessions that are not a list count as
    none."""
    sessions = _manifest(experiment).get("sessions")
    sessions = sessions if isinstance(sessions, list) else []
    recorded = [_recorded_seconds(session) for session in sessions]
    total = sum(seconds for seconds in recorded if seconds is not None)
    return total, len(sessions), sum(seconds is None for seconds in recorded)


def _manifest(experiment: str | Path | Mapping[str, Any]) -> Mapping[str, Any]:
    """A manifest given as itself or by its experiment folder."""
    if isinstance(experiment, Mapping):
        return experiment
    path = manifest_path(Path(experiment))
    return checked_manifest(read_json(path), path)


def sessions_with_other_result_path(
    experiment: str | Path | Mapping[str, Any],
) -> list[dict[str, Any]]:
    """The sessions of ``experiment`` (a folder or its manifest) whose results came from
    another result path than this code's (:data:`lonlib.storage.result_path.RESULT_PATH_VERSION`):
    one entry per such session with its ``index``, ``started`` and
    ``result_path_version`` (None for sessions recorded before versions were kept)."""
    return [
        {
            "index": index,
            "started": session.get("started"),
            "result_path_version": session.get("result_path_version"),
        }
        for index, session in enumerate(_manifest(experiment).get("sessions", []))
        if session.get("result_path_version") != RESULT_PATH_VERSION
    ]


def capability_change(manifest: Mapping[str, Any], capability: str | None) -> str | None:
    """A message when the manifest's earlier sessions recorded other torch CPU kernels
    than ``capability`` (their trials then differ in the last bits from what this session
    would compute for them); None when they agree or recorded none."""
    sessions = list(manifest.get("sessions", []))[:-1]  # the last one is this session
    before = sorted(
        {
            str(session["cpu"]["torch"])
            for session in sessions
            if isinstance(session.get("cpu"), Mapping) and session["cpu"].get("torch")
        }
    )
    if not before or before == [capability]:
        return None
    return (
        f"earlier sessions of this experiment computed with torch's {'/'.join(before)} CPU "
        f"kernels, this one with {capability}: runs resumed here will not be bit for bit "
        "what they would have been there (leave ATEN_CPU_CAPABILITY unset and import "
        "lonlib before using torch to get the AVX2 kernels lonlib pins)"
    )
