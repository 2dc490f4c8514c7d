"""Content digests of what an experiment stores: the seal that makes a change visible.

**What they protect against:** accidental edits, partial copies, a stale or mixed folder, a
careless hand edit of a table or a file, a removed trial or recording. **What not:** someone
who edits the data and recomputes the digests (SHA-256 in plain JSON, no key); against that,
the sealed root (``seal.json``) of a committed experiment is in git, so any change to it shows
in ``git status`` and in the history.

Layout (beside :mod:`lonlib.storage.layout`)::

    data/<experiment>/seal.json              the root: the configuration's digest, the
                                             sessions' result-path versions, each run's
                                             trial count and chain head, the recordings
                                             index, the figures and the inputs they were
                                             drawn from, the chains' configuration
    p=<p>/run_<run>/digests.json             the run's chain: per trial, the digest of its
                                             row of the trials table and of its files
                                             (optimum, history)
    data/<experiment>/manifest.json          ``"sealed": true`` once the folder is sealed

Each run's entries are chained (entry *i* hashes entry *i − 1*'s chain value) from a start
made of the run's name and the configuration's digest when the experiment was first sealed
(``chain_config``, kept in the root and in each run's ``digests.json``), and the root keeps
each run's count and head, so removing a run's last trials (rows, files and entries alike)
no longer matches the root, and a run moved in from an experiment of another configuration
is named. Folders sealed before ``chain_config`` existed keep their chains (started from the
run's name alone) until they are sealed again from scratch. The manifest records that the
folder was sealed, so a folder that lost its seal and every run's digests is tampered data,
not an unsealed one.

**Write order** (each file by atomic rename): a trial's history and optimum, the run's
``digests.json`` (the trial sealed ahead), the trials table (the run's commit point), and the
root at the session's open and close. A SIGKILL between two of them leaves a folder that reads
as *pending*, never as tampered: files of a trial the table lacks are leftovers the next run
overwrites; a trial sealed ahead of a table write that did not happen is redone by the next
process that takes the run (:func:`drop_unwritten_trials`); a run chain longer than the root's
count is recorded in the root at the next session. A row the run's digests do not seal, and
anything else that differs, is tampered data. ``lonlib analyse`` and ``lonlib record`` write
their outputs under temporary names, seal their digests ahead in the root
(:func:`seal_outputs_ahead`: ``figures.next``, ``recordings_next``), rename them into place and
reseal (:func:`reseal_outputs`; :mod:`lonlib.storage.outputs`): killed part-way, each output
is as sealed or as sealed ahead (pending), and the same command again completes it.

A folder that is not an experiment (a study's summaries) gets a ``files`` seal: each file's
digest (:func:`seal_files`, :func:`check_files_seal`).
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import re
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from fnmatch import fnmatch
from pathlib import Path
from typing import Any

import pandas as pd

from lonlib.storage.atomic import CorruptDataError, atomic_write, read_json, write_json

SEAL_NAME = "seal.json"
"""The root of an experiment's (or a folder's) seal."""
RUN_DIGESTS = "digests.json"
"""In each run's folder: the run's chain of trial digests."""
SEAL_FORMAT = 1
FIGURES_FOLDER = "figures"
RECORDINGS_FOLDER = "recordings"
RUN_FILES = ("optimum_{:04d}.npz", "history_{:04d}.parquet")
SEALED_FIELD = "sealed"
"""In the manifest: ``true`` once the folder was sealed (its seal then must be there)."""
_TRIAL_FILE = re.compile(r"(?:optimum|history)_(\d{4,})\.(?:npz|parquet)")
"""A trial's files in its run's folder (:mod:`lonlib.storage.layout`), by trial index."""


class TamperedDataError(CorruptDataError):
    """Stored data no longer matches its seal: the message names the file."""


class UnsealedDataWarning(UserWarning):
    """An experiment written before digests (or never sealed) is read: nothing can say
    whether it changed. ``lonlib verify --seal`` seals it after a full replay."""


class TamperedDataWarning(UserWarning):
    """A reader that only reports (``lonlib status``) read data that no longer match their
    seal: the message names the file, as :class:`TamperedDataError` does."""


def bytes_digest(data: bytes) -> str:
    """SHA-256 of ``data``, hex."""
    return hashlib.sha256(data).hexdigest()


def file_digest(path: Path) -> str:
    """SHA-256 of a file's bytes, hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _canonical(value: Any) -> str:
    """One stored value as text that tells every float bit and every type apart."""
    if value is None or value is pd.NA:
        return "n"
    if isinstance(value, bool) or type(value).__name__ == "bool_":
        return f"b:{bool(value)}"
    if isinstance(value, int) or type(value).__name__.startswith(("int", "uint")):
        return f"i:{int(value)}"
    if isinstance(value, float) or type(value).__name__.startswith("float"):
        value = float(value)
        return "f:nan" if math.isnan(value) else f"f:{value.hex()}"
    return f"s:{value}"


def row_digests(table: pd.DataFrame) -> list[str]:
    """The digest of each row of a trials table: its columns' names and values (every bit)."""
    columns = list(table.columns)
    return [
        bytes_digest(
            json.dumps([[c, _canonical(v)] for c, v in zip(columns, row, strict=True)]).encode()
        )
        for row in table.itertuples(index=False, name=None)
    ]


def table_row_digests(table_bytes: bytes) -> list[str]:
    """:func:`row_digests` of a trials table's parquet bytes, read as every reader reads it."""
    return row_digests(pd.read_parquet(io.BytesIO(table_bytes)))


def _run_key(run_folder: Path, root: Path) -> str:
    return run_folder.relative_to(root).as_posix()


def _chain_start(key: str, config: str | None) -> str:
    """Where a run's chain starts: its name and the configuration it was sealed under
    (``None``: a chain sealed before ``chain_config`` existed, from the name alone)."""
    if config is None:
        return bytes_digest(f"lonlib run {key}".encode())
    return bytes_digest(f"lonlib run {key} config {config}".encode())


def _entry_text(entry: Mapping[str, Any]) -> str:
    body = {k: entry[k] for k in ("index", "row", "files")}
    return json.dumps(body, sort_keys=True, separators=(",", ":"))


def _chained(
    key: str, entries: Iterable[Mapping[str, Any]], config: str | None
) -> list[dict[str, Any]]:
    """``entries`` with their chain values computed from the run's start (a rewrite sealed
    ahead, ``next``, is kept beside the chain, outside it)."""
    previous, out = _chain_start(key, config), []
    for entry in entries:
        previous = bytes_digest((previous + _entry_text(entry)).encode())
        new = {**{k: entry[k] for k in ("index", "row", "files")}, "chain": previous}
        if entry.get("next"):
            new["next"] = dict(entry["next"])
        out.append(new)
    return out


def _write_run(
    folder: Path, root: Path, entries: Iterable[Mapping[str, Any]], config: str | None
) -> None:
    """Write a run's ``digests.json``: ``entries`` chained from the run's start, under the
    chains' configuration ``config`` (None: a chain of a folder sealed before it existed)."""
    key = _run_key(folder, root)
    payload: dict[str, Any] = {"format": SEAL_FORMAT, "trials": _chained(key, entries, config)}
    if config is not None:
        payload["config"] = config
    _write(folder / RUN_DIGESTS, payload)


def _read_run(path: Path) -> tuple[list[dict[str, Any]], str | None]:
    """A run's ``digests.json``: its entries and the configuration its chain starts from."""
    payload = _read(path)
    return payload["trials"], payload.get("config")


def settle_ahead(run_folder: Path, root: Path) -> None:
    """Make a rewrite sealed ahead (``next``, :func:`seal_ahead`) the seal where the file now
    holds it, and forget the rest (a ``lonlib thin`` killed part-way, completed)."""
    path = Path(run_folder) / RUN_DIGESTS
    if not path.exists():
        return
    entries, config = _read_run(path)
    if not any(entry.get("next") for entry in entries):
        return
    for entry in entries:
        for name, digest in entry.pop("next", {}).items():
            file = Path(run_folder) / name
            if file.is_file() and file_digest(file) == digest:
                entry["files"][name] = digest
    _write_run(Path(run_folder), Path(root), entries, config)


def _write(path: Path, payload: Mapping[str, Any]) -> None:
    atomic_write(path, (json.dumps(payload, indent=1, sort_keys=True) + "\n").encode())


def _read(path: Path) -> dict[str, Any]:
    """A seal or a run's digests, read and checked for shape (TamperedDataError naming the
    file and what is wrong, never a traceback)."""
    try:
        payload = json.loads(path.read_bytes())
    except (OSError, ValueError) as error:
        raise TamperedDataError(f"{path}: cannot read the digests ({error})") from None
    if not isinstance(payload, dict) or payload.get("format") != SEAL_FORMAT:
        raise TamperedDataError(f"{path}: not a lonlib seal of format {SEAL_FORMAT}")
    problem = _shape_problem(payload, path.name == RUN_DIGESTS)
    if problem:
        raise TamperedDataError(f"{path}: not a well-formed seal ({problem})")
    return payload


def _is_digest(value: object) -> bool:
    return isinstance(value, str) and len(value) == 64


def _shape_problem(payload: dict[str, Any], run: bool) -> str | None:
    """What is malformed in a seal (``run``: a run's ``digests.json``), or None."""
    if "config" in payload and run and not _is_digest(payload["config"]):
        return "'config' is not a digest"
    if run:
        entries = payload.get("trials")
        if not isinstance(entries, list):
            return "'trials' is not a list"
        for i, entry in enumerate(entries):
            if not isinstance(entry, dict) or entry.get("index") != i:
                return f"trial entry {i} is not an object with index {i}"
            files = entry.get("files")
            if not (_is_digest(entry.get("row")) and _is_digest(entry.get("chain"))):
                return f"trial entry {i} lacks its row or chain digest"
            if not isinstance(files, dict) or not all(
                isinstance(k, str) and _is_digest(v) for k, v in files.items()
            ):
                return f"trial entry {i}'s 'files' is not a mapping of names to digests"
            if not isinstance(entry.get("next", {}), dict):
                return f"trial entry {i}'s 'next' is not a mapping"
        return None
    if payload.get("kind") == "files":
        files = payload.get("files")
        if not isinstance(files, dict) or not all(_is_digest(v) for v in files.values()):
            return "'files' is not a mapping of names to digests"
        return None
    runs = payload.get("runs", {})
    if not isinstance(runs, dict) or not all(
        isinstance(v, dict) and isinstance(v.get("trials"), int) and _is_digest(v.get("head"))
        for v in runs.values()
    ):
        return "'runs' is not a mapping of runs to their trial count and head"
    for name in ("recordings", "recordings_next"):
        recordings = payload.get(name, {})
        if not isinstance(recordings, dict) or not all(
            isinstance(v, dict) and _is_digest(v.get("sha256")) for v in recordings.values()
        ):
            return f"'{name}' is not a mapping of recordings to their trial and digest"
    for name in ("result_path_versions", "result_path_versions_next"):
        if name in payload and not isinstance(payload[name], list):
            return f"'{name}' is not a list"
    if "chain_config" in payload and not _is_digest(payload["chain_config"]):
        return "'chain_config' is not a digest"
    figures = payload.get("figures", {})
    if not isinstance(figures, dict) or not isinstance(figures.get("files", {}), dict):
        return "'figures' is not a mapping"
    drawn = figures.get("inputs_of", {})
    if not isinstance(drawn, dict) or not all(v is None or _is_digest(v) for v in drawn.values()):
        return "'figures.inputs_of' is not a mapping of figures to digests"
    ahead = figures.get("next", {})
    if not (
        isinstance(ahead, dict)
        and isinstance(ahead.get("files", {}), dict)
        and all(v is None or _is_digest(v) for v in ahead.get("files", {}).values())
        and (ahead.get("inputs") is None or _is_digest(ahead.get("inputs")))
    ):
        return "'figures.next' is not a mapping of figures to digests (or None) and their inputs"
    return None


def is_sealed(root: Path) -> bool:
    """Whether the folder has a seal (:data:`SEAL_NAME`)."""
    return (Path(root) / SEAL_NAME).is_file()


def config_digest(manifest: Mapping[str, Any]) -> str:
    """The digest of a manifest's configuration (its sessions may grow; its settings not)."""
    return bytes_digest(json.dumps(manifest["config"], sort_keys=True).encode())


def result_path_versions(manifest: Mapping[str, Any]) -> list[Any]:
    """The result-path version each session of a manifest recorded (None: unrecorded): they
    decide whether a replay mismatch is an error or a warning, so the root seals them."""
    sessions = manifest.get("sessions", [])
    if not isinstance(sessions, list):
        return []
    return [s.get("result_path_version") if isinstance(s, dict) else None for s in sessions]


# ----------------------------------------------------------------------------- writers


def _chains_config(old: Mapping[str, Any], manifest: Mapping[str, Any]) -> str | None:
    """The configuration digest the runs' chains start from: the current root's (None in a
    folder sealed before it existed), or the configuration's for a folder sealed now."""
    if old:
        value = old.get("chain_config")
        return value if isinstance(value, str) else None
    return config_digest(manifest)


def append_trial(
    run_folder: Path, root: Path, table_bytes: bytes, files: Mapping[str, bytes]
) -> None:
    """Seal a run's newest trial (after its table, the commit point, is written): its row's
    digest and those of ``files`` (name → the bytes just written), chained after the run's
    sealed trials. Nothing happens in an unsealed experiment (sealing it is explicit)."""
    if not is_sealed(root):
        return
    path = run_folder / RUN_DIGESTS
    if path.exists():
        entries, config = _read_run(path)
    else:  # the run's first trial: its chain starts from the root's configuration
        entries, config = [], _read(Path(root) / SEAL_NAME).get("chain_config")
    rows = table_row_digests(table_bytes)
    index = len(rows) - 1
    # an entry ahead of a table that was never written (a kill between the two) is replaced
    entries = [e for e in entries if e["index"] < index]
    if len(entries) != index:
        raise TamperedDataError(
            f"{path}: seals {len(entries)} trials, the table before trial {index} holds {index}"
        )
    files_part = {name: bytes_digest(data) for name, data in sorted(files.items())}
    entries.append({"index": index, "row": rows[index], "files": files_part})
    _write_run(run_folder, root, entries, config)


def _run_folders(root: Path) -> list[Path]:
    return sorted(p.parent for p in root.glob("p=*/run_*/trials.parquet"))


def _sealed_runs(root: Path) -> dict[str, dict[str, Any]]:
    """Each run's sealed count and chain head, from its ``digests.json``."""
    runs = {}
    for folder in sorted(p.parent for p in root.glob(f"p=*/run_*/{RUN_DIGESTS}")):
        entries, _ = _read_run(folder / RUN_DIGESTS)
        if entries:
            runs[_run_key(folder, root)] = {"trials": len(entries), "head": entries[-1]["chain"]}
    return runs


def inputs_digest(seal: Mapping[str, Any]) -> str:
    """The digest of what figures and tables are computed from: the configuration and every
    run's sealed trials."""
    body = {"config": seal.get("config"), "runs": seal.get("runs", {})}
    return bytes_digest(json.dumps(body, sort_keys=True).encode())


def _inputs_now(root: Path, seal: Mapping[str, Any]) -> str:
    """:func:`inputs_digest` of the trials as the runs' chains hold them now (a session may
    have sealed trials the root does not count yet)."""
    return inputs_digest({"config": seal.get("config"), "runs": _sealed_runs(root)})


def figure_files(root: Path) -> list[Path]:
    """The files of an experiment's figures folder that its seal covers: all but the 3-D
    LON's HTML pages (kept out of git) and hidden files (temporaries)."""
    folder = Path(root) / FIGURES_FOLDER
    if not folder.is_dir():
        return []
    return sorted(
        p
        for p in folder.iterdir()
        if p.is_file() and p.suffix != ".html" and not p.name.startswith(".")
    )


def _drawn_from(figures: Mapping[str, Any], name: str) -> str | None:
    """The inputs digest a sealed figure was drawn from (None: not recorded)."""
    drawn = figures.get("inputs_of", {})
    if name in drawn:
        value = drawn[name]
    else:
        value = figures.get("inputs")
    return value if isinstance(value, str) else None


def _figures_ahead(root: Path, figures: Mapping[str, Any]) -> dict[str, tuple[str | None, Any]]:
    """The figures sealed ahead (``figures.next``, :func:`seal_outputs_ahead`) that the
    folder holds as sealed ahead: name → (its new digest and the inputs it was drawn from),
    or (None, None) for a figure whose removal was sealed ahead and that is gone."""
    ahead = figures.get("next") or {}
    out: dict[str, tuple[str | None, Any]] = {}
    for name, digest in ahead.get("files", {}).items():
        path = Path(root) / name
        if digest is None and not path.is_file():
            out[name] = (None, None)
        elif digest is not None and path.is_file() and file_digest(path) == digest:
            out[name] = (digest, ahead.get("inputs"))
    return out


def _figures_seal(
    root: Path,
    inputs: str,
    old: Mapping[str, Any] | None,
    written: Iterable[Path],
    stale: Mapping[str, str | None],
) -> dict[str, Any]:
    """The root's figures: the files ``written`` (their digests; drawn from ``inputs`` but
    for those ``stale`` names, drawn from the inputs given there), and the files of an
    earlier analysis that are still there and were not written again, as they were sealed
    (digest and inputs; as sealed ahead where the file holds that, an analysis that stopped
    part-way): an analysis without the conditioning keeps the conditioning's."""
    files = {Path(f).relative_to(root).as_posix(): file_digest(Path(f)) for f in written}
    drawn = {name: stale[name] for name in files if name in stale}
    old = old or {}
    ahead = {n: v for n, v in _figures_ahead(root, old).items() if v[0] is not None}
    for name in sorted({*old.get("files", {}), *ahead}):
        if name not in files and (root / name).is_file():
            files[name], recorded = ahead.get(name) or (old["files"][name], _drawn_from(old, name))
            if recorded != inputs:
                drawn[name] = recorded
    entry: dict[str, Any] = {"inputs": inputs, "files": dict(sorted(files.items()))}
    if drawn:
        entry["inputs_of"] = dict(sorted(drawn.items()))
    return entry


def write_root(
    root: Path,
    manifest: Mapping[str, Any],
    *,
    recordings: Mapping[str, Mapping[str, Any]] | None = None,
    figures: Iterable[Path] | None = None,
    stale_figures: Mapping[str, str | None] | None = None,
    next_manifest: Mapping[str, Any] | None = None,
    figures_ahead: Mapping[str, str | None] | None = None,
    recordings_ahead: Mapping[str, Mapping[str, Any]] | None = None,
) -> None:
    """Write the root seal from the runs' chains as they are now, the manifest's
    configuration, and (given) the recordings index (file name → its trial's ``p``, ``run``,
    ``index``, ``fitness``) or the figures just written (their digests and their inputs'
    digest, merged with the earlier figures still there; ``stale_figures``: those among them
    drawn from other inputs, name → that digest or None); what is not given is kept from the
    current root. ``next_manifest``: a manifest about to replace ``manifest`` with changed
    settings (sealed ahead, so that a kill between the two writes leaves either accepted).
    ``figures_ahead`` (name → the digest of its new content, None: to be removed) and
    ``recordings_ahead`` (the index the recordings folder is about to hold, each with its
    ``sha256``): outputs sealed ahead of their renames (:func:`seal_outputs_ahead`); the
    figures or recordings given later settle them. The caller holds the manifest lock and
    has checked what it read."""
    root = Path(root)
    old = _read(root / SEAL_NAME) if is_sealed(root) else {}
    seal: dict[str, Any] = {
        "format": SEAL_FORMAT,
        "kind": "experiment",
        "config": config_digest(manifest),
        "runs": _sealed_runs(root),
    }
    chains = _chains_config(old, manifest)
    if chains is not None:
        seal["chain_config"] = chains
    if next_manifest is not None and config_digest(next_manifest) != seal["config"]:
        seal["config_next"] = config_digest(next_manifest)
    seal["result_path_versions"] = result_path_versions(manifest)
    if next_manifest is not None and result_path_versions(next_manifest) != result_path_versions(
        manifest
    ):
        seal["result_path_versions_next"] = result_path_versions(next_manifest)
    if recordings is not None:
        folder = root / RECORDINGS_FOLDER
        seal["recordings"] = {
            name: {**dict(info), "sha256": file_digest(folder / name)}
            for name, info in sorted(recordings.items())
        }
    elif "recordings" in old:
        seal["recordings"] = old["recordings"]
    if recordings_ahead is not None:
        seal["recordings_next"] = {n: dict(info) for n, info in sorted(recordings_ahead.items())}
    elif recordings is None and "recordings_next" in old:
        seal["recordings_next"] = old["recordings_next"]
    if figures is not None:
        seal["figures"] = _figures_seal(
            root, inputs_digest(seal), old.get("figures"), figures, stale_figures or {}
        )
    elif "figures" in old:
        seal["figures"] = old["figures"]
    if figures_ahead is not None:
        seal["figures"] = {
            **seal.get("figures", {"files": {}}),
            "next": {"inputs": inputs_digest(seal), "files": dict(sorted(figures_ahead.items()))},
        }
    _write(root / SEAL_NAME, seal)


def refresh_root(root: Path, manifest: Mapping[str, Any]) -> None:
    """Record in the root the runs' chains where it is behind them (a session that ended
    before it updated the root); nothing when it is current or the folder unsealed."""
    root = Path(root)
    if is_sealed(root) and _read(root / SEAL_NAME).get("runs") != _sealed_runs(root):
        write_root(root, manifest)


def mark_sealed(root: Path) -> None:
    """Record in the folder's manifest that it is sealed (:data:`SEALED_FIELD`), so that a
    seal lost later reads as tampered data, not as a folder written before digests. The
    caller holds the manifest lock."""
    path = Path(root) / "manifest.json"
    manifest = read_json(path)
    if manifest.get(SEALED_FIELD) is not True:
        write_json(path, {**manifest, SEALED_FIELD: True})


def seal_runs(root: Path, manifest: Mapping[str, Any]) -> None:
    """Seal every run of ``root`` as it is now (``lonlib verify --seal``, after a full
    replay; never silently): each run's chain from its table and files (from the current
    root's chain configuration, so that a seal killed part-way is completed by sealing
    again), then the root, then the mark in the manifest (:func:`mark_sealed`)."""
    root = Path(root)
    config = _chains_config(_read(root / SEAL_NAME) if is_sealed(root) else {}, manifest)
    for folder in _run_folders(root):
        table_bytes = (folder / "trials.parquet").read_bytes()
        entries = []
        for index, row in enumerate(table_row_digests(table_bytes)):
            names = [n.format(index) for n in RUN_FILES if (folder / n.format(index)).is_file()]
            entries.append(
                {"index": index, "row": row, "files": {n: file_digest(folder / n) for n in names}}
            )
        _write_run(folder, root, entries, config)
    write_root(root, manifest)
    mark_sealed(root)


def stale_figures(root: Path) -> dict[str, str | None]:
    """The figure files of ``root`` (:func:`figure_files`) that were not drawn from its trials
    as they are now: name → the inputs digest its seal recorded (None: never recorded).
    ``lonlib verify --seal`` seals them so, and they stay stale until ``lonlib analyse``."""
    root = Path(root)
    seal = _read(root / SEAL_NAME) if is_sealed(root) else {}
    figures = seal.get("figures", {})
    ahead = _figures_ahead(root, figures)
    now = _inputs_now(root, seal) if seal else None
    out: dict[str, str | None] = {}
    for path in figure_files(root):
        name = path.relative_to(root).as_posix()
        drawn = _drawn_from(figures, name) if name in figures.get("files", {}) else None
        if name in ahead:  # as an analysis that stopped part-way sealed it ahead
            drawn = ahead[name][1]
        if drawn is None or drawn != now:
            out[name] = drawn
    return out


def seal_ahead(root: Path, digests: Mapping[Path, str]) -> None:
    """Before a legitimate rewrite of sealed run files (``lonlib thin``): their new digests
    beside the old in their runs' entries (``next``), so a kill part-way leaves every file
    accepted; :func:`reseal_files` then makes the new ones the seal."""
    root = Path(root)
    by_run: dict[Path, dict[str, str]] = {}
    for path, digest in digests.items():
        by_run.setdefault(Path(path).parent, {})[Path(path).name] = digest
    for folder, names in by_run.items():
        path = folder / RUN_DIGESTS
        if not path.exists():
            continue
        entries, config = _read_run(path)
        for entry in entries:
            ahead = {n: d for n, d in names.items() if n in entry["files"]}
            if ahead:
                entry["next"] = {**entry.get("next", {}), **ahead}
        _write_run(folder, root, entries, config)


def reseal_files(root: Path, manifest: Mapping[str, Any], paths: Iterable[Path]) -> None:
    """After a legitimate rewrite of sealed run files (``lonlib thin``): their new digests in
    their runs' chains, then the root. The caller checked the seal before writing."""
    root = Path(root)
    by_run: dict[Path, list[Path]] = {}
    for path in paths:
        by_run.setdefault(Path(path).parent, []).append(Path(path))
    for folder, changed in by_run.items():
        digests = folder / RUN_DIGESTS
        if not digests.exists():
            continue
        entries, config = _read_run(digests)
        names = {p.name: file_digest(p) for p in changed}
        for entry in entries:
            entry["files"] = {n: names.get(n, d) for n, d in entry["files"].items()}
            entry.pop("next", None)
        _write_run(folder, root, entries, config)
    write_root(root, manifest)


def reseal_outputs(
    root: Path,
    *,
    figures: Iterable[Path] | None = None,
    recordings: Mapping[str, Mapping[str, Any]] | None = None,
    stale_figures: Mapping[str, str | None] | None = None,
) -> bool:
    """After ``lonlib analyse`` (``figures``: the files it wrote; its HTML pages, kept out of
    git, are left out; the earlier figures still there are kept, :func:`write_root`) or
    ``lonlib record`` (``recordings``: the index of every recording in the folder): their
    digests in the root seal, under the manifest lock. ``stale_figures``: figures not drawn
    from the trials as they are (``lonlib verify --seal``, :func:`stale_figures`). Nothing
    in an unsealed folder (returns False)."""
    from lonlib.storage.layout import MANIFEST_LOCK, read_manifest
    from lonlib.storage.lock import exclusive_lock

    root = Path(root)
    if not is_sealed(root):
        return False
    kept = None if figures is None else [Path(f) for f in figures if Path(f).suffix != ".html"]
    with exclusive_lock(root / MANIFEST_LOCK, record_holder=False):
        write_root(
            root,
            read_manifest(root),
            recordings=recordings,
            figures=kept,
            stale_figures=stale_figures,
        )
    return True


def seal_outputs_ahead(
    root: Path,
    *,
    figures: Mapping[str, str | None] | None = None,
    recordings: Mapping[str, Mapping[str, Any]] | None = None,
) -> bool:
    """Before ``lonlib analyse`` or ``lonlib record`` puts its outputs in place (each file
    written under a temporary name first, then renamed): ``figures`` (name relative to the
    root → the digest of its new content, None for a figure it removes) or ``recordings``
    (the index the recordings folder will hold, each entry with its ``sha256``) sealed
    ahead in the root, under the manifest lock, so that a kill between two renames, or
    before the reseal (:func:`reseal_outputs`) that settles them, leaves every file
    accepted as sealed or as sealed ahead (pending, never tampered). Nothing in an unsealed
    folder (returns False)."""
    from lonlib.storage.layout import MANIFEST_LOCK, read_manifest
    from lonlib.storage.lock import exclusive_lock

    root = Path(root)
    if not is_sealed(root):
        return False
    with exclusive_lock(root / MANIFEST_LOCK, record_holder=False):
        write_root(root, read_manifest(root), figures_ahead=figures, recordings_ahead=recordings)
    return True


# ----------------------------------------------------------------------------- checks


@dataclass
class SealCheck:
    """What :func:`check_experiment_seal` (or :func:`check_files_seal`) found."""

    folder: Path
    sealed: bool
    problems: list[tuple[str, str]] = field(default_factory=list)
    """(file, what differs): tampered data (errors)."""
    pending: list[tuple[str, str]] = field(default_factory=list)
    """(file, what): an interrupted write's leftovers, which the next run completes."""
    sealed_trials: dict[str, int] = field(default_factory=dict)
    """Per run (``p=<p>/run_<run>``): the trials sealed (the run's state on resume)."""

    @property
    def ok(self) -> bool:
        """No tampered data (pending writes allowed)."""
        return not self.problems

    def message(self, reader: str | None = None, refused: bool = True) -> str:
        """One line naming the first file that differs and ``reader``, the command that
        stops on it (``refused``) or reads it all the same, pointing to ``lonlib verify``;
        empty when nothing differs."""
        if not self.problems:
            return ""
        name, what = self.problems[0]
        more = f" (and {len(self.problems) - 1} more)" if len(self.problems) > 1 else ""
        said = ""
        if reader:
            said = f", so `{reader}` stops" if refused else f" (`{reader}` shows it as it is)"
        return (
            f"{self.folder / name}: {what}{more}; the data no longer matches its seal{said}: "
            f"`lonlib verify {self.folder}` lists every difference"
        )

    def raise_if_tampered(self, reader: str | None = None) -> None:
        """TamperedDataError with one line naming the first file that differs (and
        ``reader``, the command that refuses it)."""
        if self.problems:
            raise TamperedDataError(self.message(reader))


def check_experiment_seal(
    root: Path,
    manifest: Mapping[str, Any],
    *,
    figures: bool = True,
    recordings: bool = True,
    files: bool = True,
) -> SealCheck:
    """Compare an experiment folder with its seal: configuration, each run's trials (rows,
    chain, count against the root and, with ``files``, the trials' files), and (asked) the
    recordings and figures."""
    root = Path(root)
    check = SealCheck(root, is_sealed(root))
    if not check.sealed:
        _check_lost_seal(check, root, manifest, files)
        return check
    try:
        seal = _read(root / SEAL_NAME)
    except TamperedDataError as error:
        check.problems.append((SEAL_NAME, str(error).split(": ", 1)[-1]))
        return check
    if seal.get("kind") != "experiment":
        check.problems.append((SEAL_NAME, "seals a folder of files, not an experiment"))
        return check
    if config_digest(manifest) not in (seal.get("config"), seal.get("config_next")):
        check.problems.append(("manifest.json", "its configuration differs from the sealed one"))
    if "result_path_versions" in seal and result_path_versions(manifest) not in (
        seal["result_path_versions"],
        seal.get("result_path_versions_next"),
    ):  # a root sealed before they were sealed says nothing about them
        check.problems.append(
            (
                "manifest.json",
                "its sessions' result-path versions differ from the sealed ones (they decide "
                "whether a replay mismatch is an error)",
            )
        )
    sealed_runs = seal.get("runs", {})
    folders = {_run_key(f, root): f for f in _run_folders(root)}
    for key in sorted(set(sealed_runs) - set(folders)):
        check.problems.append((f"{key}/trials.parquet", "a sealed run's trials table is missing"))
    for key, folder in folders.items():
        run = _SealedRun(key, folder, sealed_runs.get(key), seal.get("chain_config"))
        _check_run(check, run, files)
    if recordings:
        _check_recordings(check, root, seal.get("recordings"), seal.get("recordings_next"))
    if figures:
        _check_figures(check, root, seal)
    return check


def _check_lost_seal(
    check: SealCheck, root: Path, manifest: Mapping[str, Any], files: bool = True
) -> None:
    """A folder without its root seal: tampered if its runs hold digests or its manifest
    records that it was sealed (a lost seal is not an old experiment), else unsealed. The
    runs that hold digests are checked against them (their tables and, with ``files``,
    files): when every one matches, the lost root reads as an interrupted ``verify --seal``
    (which sealing again completes), else each difference is named."""
    chained = sorted(root.glob(f"p=*/run_*/{RUN_DIGESTS}"))
    if chained:  # written with digests: a lost root is not an old experiment
        check.sealed = True
        # every run that holds digests must match them exactly: only then is the lost root
        # an interrupted `verify --seal` (it seals each run from its table, then the root)
        for folder in (p.parent for p in chained):
            key = _run_key(folder, root)
            _check_run(check, _SealedRun(key, folder, None, None, rootless=True), files)
        if check.problems:
            check.problems.append(
                (
                    SEAL_NAME,
                    "missing, and the runs' digests do not match their tables and files "
                    "(named): not an interrupted seal",
                )
            )
        else:
            check.problems.append(
                (SEAL_NAME, f"missing, while {len(chained)} run(s) hold their digests")
            )
    elif manifest.get(SEALED_FIELD) is True:
        check.sealed = True
        check.problems.append(
            (
                SEAL_NAME,
                "missing, while the manifest records that the folder was sealed (the seal and "
                "every run's digests are gone)",
            )
        )


@dataclass(frozen=True)
class _SealedRun:
    """A run's folder as the root seals it: ``sealed`` its count and head (None: not in the
    root), ``chains`` the configuration its chain must start from (None: a root sealed
    before chain configurations, which accepts the run's own)."""

    key: str
    folder: Path
    sealed: Mapping[str, Any] | None
    chains: str | None
    rootless: bool = False
    """The root seal is missing: the run's digests must seal its table exactly (what
    ``verify --seal`` writes before the root), nothing sealed ahead nor pending."""


def _check_run(check: SealCheck, run: _SealedRun, files: bool) -> None:
    # the table before the digests: a trial appended meanwhile then reads as sealed ahead
    table = run.folder / "trials.parquet"
    try:
        table_bytes: bytes | None = table.read_bytes()
    except OSError:
        table_bytes = None
    entries = _run_entries(check, run)
    if entries is None or not _check_head(check, run, entries):
        return
    try:
        if table_bytes is None:
            raise OSError("cannot read the file")
        rows = table_row_digests(table_bytes)
    except Exception as error:  # pyarrow raises several types for a damaged file
        check.problems.append((f"{run.key}/trials.parquet", f"cannot be read ({error})"))
        return
    _check_rows(check, run, entries, rows)
    if files:
        _check_trial_files(check, run, entries[: len(rows)])
    check.sealed_trials[run.key] = min(len(entries), len(rows))
    _check_stray_files(check, run, entries, len(rows))


def _run_entries(check: SealCheck, run: _SealedRun) -> list[dict[str, Any]] | None:
    """A run's sealed entries, once its chain holds from the experiment's start (None,
    the problem noted, when it does not)."""
    digests = run.folder / RUN_DIGESTS
    name = f"{run.key}/{RUN_DIGESTS}"
    if not digests.exists():
        return []
    try:
        entries, config = _read_run(digests)
    except TamperedDataError as error:
        check.problems.append((name, str(error).split(": ", 1)[-1]))
        return None
    if run.chains is not None and config != run.chains:
        check.problems.append(
            (
                name,
                "chained from another configuration than this experiment's (another "
                "experiment's run?)",
            )
        )
        return None
    if [e.get("chain") for e in entries] != [
        e["chain"] for e in _chained(run.key, entries, config)
    ]:
        check.problems.append((name, "its chain of trial digests is broken"))
        return None
    return entries


def _check_head(check: SealCheck, run: _SealedRun, entries: list[dict[str, Any]]) -> bool:
    """Whether the run still holds the trials the root counts, up to its head (else the
    problem is noted)."""
    if run.sealed is None:
        return True
    count = int(run.sealed["trials"])
    if len(entries) < count or entries[count - 1]["chain"] != run.sealed["head"]:
        check.problems.append(
            (
                f"{run.key}/trials.parquet",
                f"the seal holds {count} trials of this run and they are not all here "
                f"({len(entries)} sealed in the run): trials were removed or rewritten",
            )
        )
        return False
    return True


def _check_rows(
    check: SealCheck, run: _SealedRun, entries: list[dict[str, Any]], rows: list[str]
) -> None:
    """The table's rows against the run's entries and the root's count."""
    key = run.key
    count = 0 if run.sealed is None else int(run.sealed["trials"])
    if len(rows) < count:
        check.problems.append(
            (f"{key}/trials.parquet", f"holds {len(rows)} trials, the seal holds {count}")
        )
    elif run.rootless and len(rows) < len(entries):
        check.problems.append(
            (
                f"{key}/trials.parquet",
                f"holds {len(rows)} trials, its run's digests seal {len(entries)} (and the "
                "root seal is missing): trials were removed",
            )
        )
    elif len(rows) < len(entries):
        check.pending.append(
            (
                f"{key}/{RUN_DIGESTS}",
                f"{len(entries) - len(rows)} trial(s) sealed ahead of a table write that did not "
                "happen (an interrupted write): the next process that takes the run redoes them",
            )
        )
    for entry, row in zip(entries, rows, strict=False):
        if entry["row"] != row:
            check.problems.append(
                (f"{key}/trials.parquet", f"trial {entry['index']}'s row differs from its seal")
            )
    if len(rows) > len(entries):
        check.problems.append(
            (
                f"{key}/trials.parquet",
                f"holds {len(rows) - len(entries)} trial(s) its run's digests do not seal "
                "(rows added after the seal)",
            )
        )
    if len(entries) > count and not run.rootless:
        check.pending.append(
            (
                f"{key}/{RUN_DIGESTS}",
                f"{len(entries) - count} trial(s) sealed in the run and not yet in the root "
                f"({SEAL_NAME}): a session in progress or interrupted; the next session or "
                "`lonlib verify --seal` records them",
            )
        )


def _check_trial_files(check: SealCheck, run: _SealedRun, entries: list[dict[str, Any]]) -> None:
    """Each sealed trial's files (optimum, history) against their digests."""
    for entry in entries:
        for name, digest in entry["files"].items():
            path = run.folder / name
            accepted = (digest, entry.get("next", {}).get(name))  # a rewrite sealed ahead
            if not path.is_file():
                check.problems.append((f"{run.key}/{name}", "a sealed file is missing"))
            elif file_digest(path) not in accepted:
                check.problems.append((f"{run.key}/{name}", "differs from its seal"))


def _check_stray_files(
    check: SealCheck, run: _SealedRun, entries: list[dict[str, Any]], rows: int
) -> None:
    """A trial's file no seal lists: a leftover of a trial the table lacks (pending), or
    tampered data."""
    sealed_names = {n for e in entries[:rows] for n in e["files"]}
    for path in sorted(run.folder.iterdir()):
        match = _TRIAL_FILE.fullmatch(path.name)
        if match is None or path.name in sealed_names:
            continue  # not a trial's file (a temporary, the table, the lock), or sealed
        if int(match.group(1)) >= rows:
            check.pending.append((f"{run.key}/{path.name}", "a leftover of an unsealed trial"))
        else:
            check.problems.append((f"{run.key}/{path.name}", "a file no seal lists"))


def _check_recordings(
    check: SealCheck,
    root: Path,
    index: Mapping[str, Mapping[str, Any]] | None,
    ahead: Mapping[str, Mapping[str, Any]] | None = None,
) -> None:
    """The recordings against the index (a recording that holds what ``ahead``, the index
    sealed ahead of a ``lonlib record`` that stopped before it resealed, lists is pending)."""
    folder = root / RECORDINGS_FOLDER
    present = {p.name for p in folder.glob("*.rrd")} if folder.is_dir() else set()
    if ahead:
        check.pending.append(
            (
                SEAL_NAME,
                "recordings sealed ahead of a `lonlib record` that stopped before it finished "
                "putting them in place: `lonlib record` again completes it",
            )
        )
    new = {  # a recording put in place as sealed ahead
        name
        for name in present & set(ahead or {})
        if file_digest(folder / name) == (ahead or {})[name].get("sha256")
    }
    listed = dict(index or {})
    if index is None and present - new:
        check.problems.append(
            (
                RECORDINGS_FOLDER,
                f"{len(present - new)} recordings and no recordings index in the seal",
            )
        )
        return
    for name in sorted(set(listed) - present):
        info = listed[name]
        renamed = [
            n for n in present - set(listed) if file_digest(folder / n) == info.get("sha256")
        ]
        what = f"renamed to {renamed[0]}" if renamed else "missing"
        check.problems.append(
            (
                f"{RECORDINGS_FOLDER}/{name}",
                f"the recording of p={info.get('p')}, run {info.get('run')}, trial "
                f"{info.get('index')} (f = {info.get('fitness')}) is {what}",
            )
        )
    for name in sorted(present - set(listed) - new):
        check.problems.append((f"{RECORDINGS_FOLDER}/{name}", "not in the recordings index"))
    for name in sorted((present & set(listed)) - new):
        if file_digest(folder / name) != listed[name].get("sha256"):
            check.problems.append(
                (
                    f"{RECORDINGS_FOLDER}/{name}",
                    "differs from its seal (a recording: `lonlib record` regenerates it)",
                )
            )


def _check_figures(check: SealCheck, root: Path, seal: Mapping[str, Any]) -> None:
    """The sealed figures and tables (each there and unchanged), the files of the figures
    folder the seal does not list, and whether they were drawn from the trials as they are."""
    figures = seal.get("figures") or {}
    listed = dict(figures.get("files", {}))
    ahead = _figures_ahead(root, figures)  # those there as sealed ahead (or removed so)
    if "next" in figures:
        check.pending.append(
            (
                SEAL_NAME,
                "figures and tables sealed ahead of a `lonlib analyse` that stopped before it "
                "finished putting them in place: `lonlib analyse` again completes it",
            )
        )
    drawn = {name: _drawn_from(figures, name) for name in listed}
    drawn.update({name: inputs for name, (digest, inputs) in ahead.items() if digest})
    for name, digest in sorted(listed.items()):
        path = root / name
        if name in ahead:
            continue  # as sealed ahead (or removed so)
        if not path.is_file():
            check.problems.append(
                (name, "a sealed figure or table is missing (`lonlib analyse` regenerates it)")
            )
        elif file_digest(path) != digest:
            check.problems.append(
                (name, "differs from its seal (a figure: `lonlib analyse` regenerates it)")
            )
    for path in figure_files(root):
        name = path.relative_to(root).as_posix()
        if name in ahead:
            continue
        if name not in listed:
            check.problems.append(
                (
                    name,
                    "a figure or table the seal does not list (added by hand, or written by an "
                    "analysis that stopped before sealing it: `lonlib analyse` again)",
                )
            )
    drawn = {name: inputs for name, inputs in drawn.items() if (root / name).is_file()}
    now = _inputs_now(root, seal) if drawn else None
    stale = [name for name in sorted(drawn) if drawn[name] != now]
    if stale:
        check.pending.append(
            (
                FIGURES_FOLDER,
                f"{len(stale)} of {len(drawn)} figures and tables ({stale[0]}"
                f"{', ...' if len(stale) > 1 else ''}) made from an earlier state of the "
                "trials (stale): `lonlib analyse` again",
            )
        )


def check_readable(
    root: Path,
    manifest: Mapping[str, Any],
    reader: str = "lonlib analyse",
    *,
    refuse: bool = True,
    files: bool = True,
) -> SealCheck:
    """A reader's gate (``lonlib run`` on resume, ``analyse``, ``lon``, ``record``,
    ``thin``; ``reader`` names it in the message): stop with one line naming the file that
    differs from the seal, before any compute; warn (:class:`UnsealedDataWarning`) when the
    folder has no seal. A reader that only reports (``lonlib status``: ``refuse`` False)
    warns instead (:class:`TamperedDataWarning`), and checks what it reads (``files``
    False: the trials tables and the chains, not every trial's files). Figures and
    recordings are checked by ``lonlib verify`` (a reader of trials does not read them)."""
    check = check_experiment_seal(root, manifest, figures=False, recordings=False, files=files)
    if not check.sealed:
        warnings.warn(
            f"{root}: unsealed (written before digests): `{reader}` cannot tell whether it "
            f"changed since it was written; `lonlib verify {root} --seal` seals it after a "
            "full replay",
            UnsealedDataWarning,
            stacklevel=2,
        )
    if refuse:
        check.raise_if_tampered(reader)
    elif not check.ok:
        warnings.warn(check.message(reader, refused=False), TamperedDataWarning, stacklevel=2)
    return check


# --------------------------------------------------------------- folders of files (studies)


def _patterns(folder: Path) -> list[str]:
    ignore = folder / ".gitignore"
    lines = ignore.read_text().splitlines() if ignore.is_file() else []
    return [line.strip() for line in lines if line.strip() and not line.startswith("#")]


def _sealable_files(folder: Path, top: Path | None = None) -> dict[str, Path]:
    """The files of a study folder that are kept: not matched by a ``.gitignore`` on the
    way down (``*.npz``, ``inflight/``; names only, the patterns these folders use) nor
    temporaries, except the seal, the ``.gitignore`` files and any subfolder with a seal of
    its own (sealed by itself)."""
    top = folder if top is None else top
    patterns = [*_patterns(folder), ".*.tmp", "*.tmp"]
    return _walk(folder, top, patterns)


def _walk(folder: Path, top: Path, patterns: list[str]) -> dict[str, Path]:
    out: dict[str, Path] = {}
    patterns = [*patterns, *_patterns(folder)]
    for path in sorted(folder.iterdir()):
        name = path.name
        if path.is_dir():
            ignored = any(p.rstrip("/") == name for p in patterns if p.endswith("/"))
            if not ignored and not (path / SEAL_NAME).is_file():
                out.update(_walk(path, top, patterns))
        elif name not in (SEAL_NAME, ".gitignore") and not any(
            fnmatch(name, p) for p in patterns if not p.endswith("/")
        ):
            out[path.relative_to(top).as_posix()] = path
    return out


def seal_files(folder: Path) -> int:
    """Seal a folder that is not an experiment (a study's stored summaries): each kept
    file's digest. Returns the number of files sealed."""
    folder = Path(folder)
    if any(folder.glob("p=*/run_*")) or (folder / "manifest.json").exists():
        raise ValueError(f"{folder}: an experiment's folder: its seal comes from a full verify")
    if not _sealable_files(folder):
        raise ValueError(f"{folder}: no file to seal (a typo in the folder's name?)")
    return _write_files_seal(folder)


def _write_files_seal(folder: Path) -> int:
    files = _sealable_files(folder)
    _write(
        folder / SEAL_NAME,
        {
            "format": SEAL_FORMAT,
            "kind": "files",
            "files": {name: file_digest(path) for name, path in files.items()},
        },
    )
    return len(files)


def reseal_files_if_sealed(folder: Path) -> None:
    """A writer of a sealed study folder reseals what it wrote (nothing if unsealed)."""
    if is_sealed(folder):
        _write_files_seal(Path(folder))


def check_files_seal(folder: Path) -> SealCheck:
    """Compare a ``files`` seal with the folder: a missing or changed file is a problem, a
    kept file the seal does not list is pending (written since; sealed by the next writer
    or ``lonlib verify --seal``)."""
    folder = Path(folder)
    check = SealCheck(folder, is_sealed(folder))
    if not check.sealed:
        return check
    try:
        seal = _read(folder / SEAL_NAME)
    except TamperedDataError as error:
        check.problems.append((SEAL_NAME, str(error).split(": ", 1)[-1]))
        return check
    if seal.get("kind") != "files":
        check.problems.append(
            ("manifest.json", "missing: the seal is an experiment's, and its manifest is gone")
        )
        return check
    listed = seal.get("files", {})
    present = _sealable_files(folder)
    for name, digest in sorted(listed.items()):
        if name not in present:
            check.problems.append((name, "a sealed file is missing"))
        elif file_digest(present[name]) != digest:
            check.problems.append((name, "differs from its seal"))
    for name in sorted(set(present) - set(listed)):
        check.pending.append((name, "not in the seal (written since it was sealed)"))
    return check


def drop_unwritten_trials(run_folder: Path, root: Path) -> int:
    """Drop a run's digests entries sealed ahead of a table write that never happened (a kill
    between the two, or a failed table write): the next local search redoes that trial.
    Called by the process that takes the run (holding its lock) after the folder's seal was
    checked; nothing in an unsealed experiment. Returns the number of entries dropped."""
    root, run_folder = Path(root), Path(run_folder)
    path = run_folder / RUN_DIGESTS
    if not is_sealed(root) or not path.exists():
        return 0
    entries, config = _read_run(path)
    table = run_folder / "trials.parquet"
    rows = len(table_row_digests(table.read_bytes())) if table.exists() else 0
    if len(entries) <= rows:
        return 0
    kept = entries[:rows]
    _write_run(run_folder, root, kept, config)
    return len(entries) - rows


__all__ = [
    "RUN_DIGESTS",
    "SEALED_FIELD",
    "SEAL_NAME",
    "SealCheck",
    "TamperedDataError",
    "TamperedDataWarning",
    "UnsealedDataWarning",
    "append_trial",
    "check_experiment_seal",
    "check_files_seal",
    "check_readable",
    "figure_files",
    "file_digest",
    "is_sealed",
    "mark_sealed",
    "reseal_files",
    "reseal_files_if_sealed",
    "reseal_outputs",
    "refresh_root",
    "row_digests",
    "seal_ahead",
    "seal_files",
    "seal_outputs_ahead",
    "settle_ahead",
    "seal_runs",
    "stale_figures",
    "drop_unwritten_trials",
    "write_root",
]
