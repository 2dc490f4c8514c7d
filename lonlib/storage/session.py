"""A sampling session on an experiment folder (:class:`SamplingSession`): opening it updates the
manifest with this session (:func:`lonlib.storage.manifest.updated_manifest`), takes the folder's
sampling lock (shared, or exclusive while the session changes stored settings) and finds the runs
to do; closing it records the session's end in the manifest and lets go of the folder."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Collection
from pathlib import Path
from typing import Any

from lonlib.config import ExperimentConfig
from lonlib.storage.atomic import remove_temporary_files, write_json
from lonlib.storage.digests import (
    SEALED_FIELD,
    check_readable,
    is_sealed,
    refresh_root,
    write_root,
)
from lonlib.storage.layout import MANIFEST_LOCK, SAMPLING_LOCK, read_manifest, run_dir
from lonlib.storage.lock import LockHeld, SamplingLock, exclusive_lock
from lonlib.storage.manifest import (
    manifest_path,
    mark_session_ended,
    sessions_with_other_result_path,
    updated_manifest,
)
from lonlib.storage.result_path import RESULT_PATH_VERSION
from lonlib.storage.trials import runs_ending_early

log = logging.getLogger(__name__)

Run = tuple[float, int]  # (p, run)

SESSION_END_LOCK_SECONDS = 30.0
"""How long a session waits for the manifest lock to record its end before it gives up
(logged): another session starting on the folder holds it while it reads every stored run."""


class SamplingSession:
    """One session sampling into ``out``: :meth:`open` it, do :attr:`todo`, :meth:`close` it
    (however the sampling stopped). ``manifest`` is the manifest with this session last."""

    def __init__(
        self,
        out: Path,
        manifest: dict[str, Any],
        todo: list[Run],
        sampling: SamplingLock,
        recorded: bool,
        started: float,
    ) -> None:
        self.out, self.manifest, self.todo = out, manifest, todo
        self.sampling, self.recorded, self.started = sampling, recorded, started

    @classmethod
    def open(
        cls,
        out: Path,
        config: ExperimentConfig,
        provenance: dict[str, Any],
        allow_changes: Collection[str],
        pending: Callable[[], list[Run]],
        tidy: Callable[[list[Run]], None],
        held_by_another: Callable[[Run], bool],
        started: float,
    ) -> SamplingSession:
        """Under the manifest lock: this session in the manifest (``provenance``; the
        settings ``allow_changes`` names may change), the sampling lock held
        (:func:`_hold_sampling_lock`; ``held_by_another`` says whether another process holds
        a run's lock), the runs to do (``pending()``, which reads every stored run: a corrupt
        file stops the session), refused if the folder holds another result-path version, and
        ``tidy(todo)`` (the experiment's leftovers of ended runs). The manifest is written
        unless the experiment is finished and its settings stay. ``started``: the session's
        start (``time.monotonic()``), from which its wall time counts."""
        sampling = SamplingLock(out / SAMPLING_LOCK)
        try:
            with exclusive_lock(out / MANIFEST_LOCK, record_holder=False):
                remove_temporary_files(out, manifest_path(out).name)
                new = not manifest_path(out).exists()
                if not new:  # what is resumed must be what was sealed, before any compute
                    check_readable(out, read_manifest(out), "lonlib run")
                manifest = updated_manifest(config, out, provenance, allow_changes)
                changed = bool(manifest["sessions"][-1].get("changed"))
                _hold_sampling_lock(out, manifest, sampling, changed, held_by_another)
                todo = pending()  # reads every stored run: a corrupt file stops us
                if todo and manifest_path(out).exists():
                    refuse_mixed_result_paths(out)
                tidy(todo)
                recorded = bool(todo) or changed or not manifest_path(out).exists()
                if recorded:  # a finished experiment stays untouched, unless its settings change
                    # Sealed ahead of the manifest (a new experiment from its start; changed
                    # settings accepted beside the old), then as written; the manifest
                    # records that the folder is sealed (a lost seal is then tampered data).
                    sealed = new or is_sealed(out)
                    if sealed:
                        manifest[SEALED_FIELD] = True
                        stored = manifest if new else read_manifest(out)
                        write_root(out, stored, next_manifest=manifest)
                    write_json(manifest_path(out), manifest)
                    if sealed:
                        write_root(out, manifest)
                else:  # an interrupted session's runs, sealed in their folders, in the root
                    refresh_root(out, read_manifest(out))
                sampling.share()
        except BaseException:
            sampling.release()
            raise
        return cls(out, manifest, todo, sampling, recorded, started)

    def failed_write(self) -> None:
        """The session stops on a failed write: it writes nothing more (no recorded end)."""
        self.recorded = False

    def close(self) -> None:
        """Record the session's end (its wall time) in the manifest if it was recorded (best
        effort: :func:`_record_session_end`), then let go of the folder, however that went."""
        try:
            if self.recorded:
                seconds = time.monotonic() - self.started
                _record_session_end(self.out, self.manifest["sessions"][-1]["id"], seconds)
        finally:  # a session that ends, however, lets go of the folder
            self.sampling.release()


def refuse_mixed_result_paths(out: Path) -> None:
    """Refuse to sample more into an experiment whose stored sessions ran another
    result-path version (:mod:`lonlib.storage.result_path`): no experiment mixes two versions of a
    result-changing path. Analysing it (``lonlib analyse``, ``lonlib verify``) still works."""
    others = sessions_with_other_result_path(out)
    if others:
        found = sorted({str(s["result_path_version"]) for s in others})
        raise ValueError(
            f"{out} was sampled by result-path version(s) {found} ('None': before versions "
            f"were recorded) and this lonlib computes version {RESULT_PATH_VERSION}: its "
            "runs cannot be continued or extended without mixing two versions of the results. "
            "Analyse it as it is (lonlib analyse / lonlib verify), or sample the experiment "
            "again into a new folder (--out)"
        )


def _hold_sampling_lock(
    out: Path,
    manifest: dict[str, Any],
    sampling: SamplingLock,
    changed: bool,
    held_by_another: Callable[[Run], bool],
) -> None:
    """Hold ``out``'s sampling lock for this session: shared, or exclusively when the session
    changes the stored settings (``allow_changes``), refused with a ValueError while another
    session samples (under the old settings). Runs another process holds refuse a change
    too: a session of an older lonlib holds run locks but no sampling lock."""
    try:
        sampling.acquire(exclusive=changed)
    except LockHeld:
        held = True
    else:
        held = False
        if changed:
            config = manifest["config"]
            started = [
                (p, run)
                for p in config["perturbations"]
                for run in range(config["runs"])
                if run_dir(out, p, run).exists()
            ]
            held = any(held_by_another(run) for run in started)
            if not held:  # a search stored past the new cap before we held the lock
                early = runs_ending_early(out, ExperimentConfig.from_mapping(config).basin_hopping)
                if early:
                    sampling.release()
                    raise ValueError(
                        f"{out}: cannot change {sorted(manifest['sessions'][-1]['changed'])}: "
                        f"stored run(s) go on past the new settings: {'; '.join(early[:5])}"
                    )
    if held:
        sampling.release()
        raise ValueError(
            f"{out}: another process is sampling this experiment; stop it before changing "
            f"{sorted(manifest['sessions'][-1]['changed'])}"
        )


def _record_session_end(out: Path, session_id: str, seconds: float) -> None:
    """The session's end in the manifest (its measured wall time). Best effort: a folder or
    manifest that is gone is left gone, and any failure to write the end (the lock held past
    :data:`SESSION_END_LOCK_SECONDS`, a disk error, a manifest edited into another shape) is
    logged, never raised, so it cannot hide the error that may be ending the session."""
    if not manifest_path(out).is_file():
        return
    deadline = time.monotonic() + SESSION_END_LOCK_SECONDS
    try:
        while True:
            try:
                with exclusive_lock(out / MANIFEST_LOCK, wait=False, record_holder=False):
                    mark_session_ended(out, session_id, seconds)
                    if is_sealed(out):  # the runs' chains as this session leaves them
                        write_root(out, read_manifest(out))
                return
            except LockHeld:
                if time.monotonic() >= deadline:
                    raise
                time.sleep(0.2)
    except Exception as error:  # noqa: BLE001  (logged: see the docstring)
        log.warning("%s: could not record this session's end in the manifest: %s", out, error)
