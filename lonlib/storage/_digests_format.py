"""What a seal holds and how it is read and written (:mod:`lonlib.storage.digests`): its
names and format, the digests of bytes, files and table rows, each run's chain of trial
entries, the seal files read and checked for shape, and what figures are drawn from."""

from __future__ import annotations

import hashlib
import io
import json
import math
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from lonlib.storage.atomic import CorruptDataError, atomic_write

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


TRIAL_FILE = re.compile(r"(?:optimum|history)_(\d{4,})\.(?:npz|parquet)")
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


def run_key(run_folder: Path, root: Path) -> str:
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


def chained(
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


def write_run(
    folder: Path, root: Path, entries: Iterable[Mapping[str, Any]], config: str | None
) -> None:
    """Write a run's ``digests.json``: ``entries`` chained from the run's start, under the
    chains' configuration ``config`` (None: a chain of a folder sealed before it existed)."""
    key = run_key(folder, root)
    payload: dict[str, Any] = {"format": SEAL_FORMAT, "trials": chained(key, entries, config)}
    if config is not None:
        payload["config"] = config
    write_seal(folder / RUN_DIGESTS, payload)


def read_run(path: Path) -> tuple[list[dict[str, Any]], str | None]:
    """A run's ``digests.json``: its entries and the configuration its chain starts from."""
    payload = read_seal(path)
    return payload["trials"], payload.get("config")


def write_seal(path: Path, payload: Mapping[str, Any]) -> None:
    atomic_write(path, (json.dumps(payload, indent=1, sort_keys=True) + "\n").encode())


def read_seal(path: Path) -> dict[str, Any]:
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
        bad = [n for n in recordings if not _is_file_name(n)]
        if bad:
            return f"'{name}' names {bad[0][:MAX_KEY_SHOWN]!r}, not a plain file name"
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
    for name, keys in (
        ("figures.files", figures.get("files", {})),
        ("figures.inputs_of", drawn),
        ("figures.next", ahead.get("files", {})),
    ):
        bad = [n for n in keys if not _is_figure_key(n)]
        if bad:
            return f"'{name}' names {bad[0][:MAX_KEY_SHOWN]!r}, not a file under {FIGURES_FOLDER}/"
    return None


MAX_NAME_BYTES = 255
"""The longest file name (one path part) a seal may name, in UTF-8 bytes (the common file
systems' limit)."""
MAX_KEY_CHARS = 4096
"""The longest path (figures' keys) a seal may name, in characters."""
MAX_KEY_SHOWN = 200
"""The characters of a bad key a shape error quotes."""


def _is_file_name(name: str) -> bool:
    """A plain file name: no folder, not ``.`` or ``..``, at most :data:`MAX_NAME_BYTES`
    bytes in UTF-8."""
    return (
        isinstance(name, str)
        and bool(name)
        and name not in (".", "..")
        and not set(name) & {"/", "\\", "\0"}
        and len(name.encode("utf-8", "surrogatepass")) <= MAX_NAME_BYTES
    )


def _is_figure_key(name: str) -> bool:
    """A relative POSIX path of a file under the figures folder, with no ``..``, at most
    :data:`MAX_KEY_CHARS` characters, each part a plain file name (:func:`_is_file_name`)."""
    if not isinstance(name, str) or len(name) > MAX_KEY_CHARS:
        return False
    parts = name.split("/")
    return (
        len(parts) >= 2
        and parts[0] == FIGURES_FOLDER
        and all(_is_file_name(part) for part in parts[1:])
    )


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


def run_folders(root: Path) -> list[Path]:
    return sorted(p.parent for p in root.glob("p=*/run_*/trials.parquet"))


def sealed_runs(root: Path) -> dict[str, dict[str, Any]]:
    """Each run's sealed count and chain head, from its ``digests.json``."""
    runs = {}
    for folder in sorted(p.parent for p in root.glob(f"p=*/run_*/{RUN_DIGESTS}")):
        entries, _ = read_run(folder / RUN_DIGESTS)
        if entries:
            runs[run_key(folder, root)] = {"trials": len(entries), "head": entries[-1]["chain"]}
    return runs


def inputs_digest(seal: Mapping[str, Any]) -> str:
    """The digest of what figures and tables are computed from: the configuration and every
    run's sealed trials."""
    body = {"config": seal.get("config"), "runs": seal.get("runs", {})}
    return bytes_digest(json.dumps(body, sort_keys=True).encode())


def inputs_now(root: Path, seal: Mapping[str, Any]) -> str:
    """:func:`inputs_digest` of the trials as the runs' chains hold them now (a session may
    have sealed trials the root does not count yet)."""
    return inputs_digest({"config": seal.get("config"), "runs": sealed_runs(root)})


def loaded_inputs(root: Path, trials: pd.DataFrame) -> str | None:
    """:func:`inputs_digest` of the trials a reader just loaded from sealed ``root`` (its
    trials tables, after its seal check): per run, as many trials as it read, by their chain
    (read after the tables, so a trial a session seals meanwhile is not counted), so that
    figures drawn from them are sealed as drawn from them. None in an unsealed folder."""
    from lonlib.storage.layout import read_manifest, run_dir

    root = Path(root)
    if not is_sealed(root):
        return None
    runs = {}
    for (p, run), count in trials.groupby(["p", "run"]).size().items():
        folder = run_dir(root, float(p), int(run))
        path = folder / RUN_DIGESTS
        entries = read_run(path)[0] if path.is_file() else []
        if len(entries) >= count:  # else not all sealed: drawn from no sealed state (stale)
            runs[run_key(folder, root)] = {
                "trials": int(count),
                "head": entries[count - 1]["chain"],
            }
    return inputs_digest({"config": config_digest(read_manifest(root)), "runs": runs})


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


def drawn_from(figures: Mapping[str, Any], name: str) -> str | None:
    """The inputs digest a sealed figure was drawn from (None: not recorded)."""
    drawn = figures.get("inputs_of", {})
    if name in drawn:
        value = drawn[name]
    else:
        value = figures.get("inputs")
    return value if isinstance(value, str) else None


def figures_ahead(root: Path, figures: Mapping[str, Any]) -> dict[str, tuple[str | None, Any]]:
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


__all__ = [
    "FIGURES_FOLDER",
    "RECORDINGS_FOLDER",
    "RUN_DIGESTS",
    "RUN_FILES",
    "SEALED_FIELD",
    "SEAL_FORMAT",
    "SEAL_NAME",
    "TRIAL_FILE",
    "TamperedDataError",
    "TamperedDataWarning",
    "UnsealedDataWarning",
    "bytes_digest",
    "chained",
    "config_digest",
    "drawn_from",
    "figure_files",
    "figures_ahead",
    "file_digest",
    "inputs_digest",
    "inputs_now",
    "is_sealed",
    "loaded_inputs",
    "read_run",
    "read_seal",
    "result_path_versions",
    "row_digests",
    "run_folders",
    "run_key",
    "sealed_runs",
    "table_row_digests",
    "write_run",
    "write_seal",
]
