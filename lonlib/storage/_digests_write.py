"""The writers of an experiment's seal (:mod:`lonlib.storage.digests`): each trial sealed
ahead of its row, the root written from the runs' chains, a folder sealed after a full
replay, rewrites and outputs sealed ahead and resealed, trials sealed ahead of a table write
that never happened dropped."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from lonlib.storage._digests_format import (
    RECORDINGS_FOLDER,
    RUN_DIGESTS,
    RUN_FILES,
    SEAL_FORMAT,
    SEAL_NAME,
    SEALED_FIELD,
    TamperedDataError,
    bytes_digest,
    config_digest,
    drawn_from,
    figure_files,
    figures_ahead,
    file_digest,
    inputs_digest,
    inputs_now,
    is_sealed,
    read_run,
    read_seal,
    result_path_versions,
    run_folders,
    sealed_runs,
    table_row_digests,
    write_run,
    write_seal,
)
from lonlib.storage.atomic import read_json, remove_temporary_files, write_json


def settle_ahead(run_folder: Path, root: Path) -> None:
    """Make a rewrite sealed ahead (``next``, :func:`seal_ahead`) the seal where the file now
    holds it, and forget the rest (a ``lonlib thin`` killed part-way, completed)."""
    path = Path(run_folder) / RUN_DIGESTS
    if not path.exists():
        return
    entries, config = read_run(path)
    if not any(entry.get("next") for entry in entries):
        return
    for entry in entries:
        for name, digest in entry.pop("next", {}).items():
            file = Path(run_folder) / name
            if file.is_file() and file_digest(file) == digest:
                entry["files"][name] = digest
    write_run(Path(run_folder), Path(root), entries, config)


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
        entries, config = read_run(path)
    else:  # the run's first trial: its chain starts from the root's configuration
        entries, config = [], read_seal(Path(root) / SEAL_NAME).get("chain_config")
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
    write_run(run_folder, root, entries, config)


def _settled_figures(root: Path, figures: Mapping[str, Any]) -> dict[str, Any]:
    """The root's ``figures`` with what it sealed ahead (``next``, :func:`seal_outputs_ahead`)
    and the folder holds made its seal (an analysis that stopped after putting them in
    place): each figure there as sealed ahead, with the inputs it was drawn from, and each
    whose removal was sealed ahead and that is gone, dropped; ``next`` itself left out."""
    out = {key: value for key, value in figures.items() if key != "next"}
    ahead = figures_ahead(root, figures)
    if not ahead:
        return out
    files = dict(out.get("files", {}))
    drawn = {name: drawn_from(figures, name) for name in files}
    for name, (digest, inputs) in ahead.items():
        if digest is None:
            files.pop(name, None)
            drawn.pop(name, None)
        else:
            files[name], drawn[name] = digest, inputs
    if not figures.get("files"):  # nothing sealed before them: their inputs are the default
        out["inputs"] = figures["next"].get("inputs")
    out["files"] = dict(sorted(files.items()))
    out.pop("inputs_of", None)
    inputs_of = {name: value for name, value in sorted(drawn.items()) if value != out.get("inputs")}
    if inputs_of:
        out["inputs_of"] = inputs_of
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
    part-way, :func:`_settled_figures`): an analysis without the conditioning keeps the
    conditioning's."""
    files = {Path(f).relative_to(root).as_posix(): file_digest(Path(f)) for f in written}
    drawn = {name: stale[name] for name in files if name in stale}
    old = _settled_figures(root, old or {})
    for name, digest in old.get("files", {}).items():
        if name not in files and (root / name).is_file():
            files[name] = digest
            recorded = drawn_from(old, name)
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
    figures_inputs: str | None = None,
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
    figures or recordings given later settle them. ``figures_inputs``: the digest of the
    trials the figures (written or sealed ahead) were drawn from, as the analysis loaded
    them (:func:`lonlib.storage.digests.loaded_inputs`; None: the trials as sealed now). The
    caller holds the manifest lock and has checked what it read."""
    root = Path(root)
    old = read_seal(root / SEAL_NAME) if is_sealed(root) else {}
    seal: dict[str, Any] = {
        "format": SEAL_FORMAT,
        "kind": "experiment",
        "config": config_digest(manifest),
        "runs": sealed_runs(root),
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
    drawn = figures_inputs or inputs_digest(seal)
    if figures is not None:
        seal["figures"] = _figures_seal(
            root, drawn, old.get("figures"), figures, stale_figures or {}
        )
    elif "figures" in old:
        seal["figures"] = old["figures"]
    if figures_ahead is not None:  # what an earlier one left sealed ahead and in place, settled
        seal["figures"] = {
            **_settled_figures(root, seal.get("figures", {"files": {}})),
            "next": {"inputs": drawn, "files": dict(sorted(figures_ahead.items()))},
        }
    write_seal(root / SEAL_NAME, seal)


def refresh_root(root: Path, manifest: Mapping[str, Any]) -> None:
    """Record in the root the runs' chains where it is behind them (a session that ended
    before it updated the root); nothing when it is current or the folder unsealed."""
    root = Path(root)
    if is_sealed(root) and read_seal(root / SEAL_NAME).get("runs") != sealed_runs(root):
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
    config = _chains_config(read_seal(root / SEAL_NAME) if is_sealed(root) else {}, manifest)
    for folder in run_folders(root):
        table_bytes = (folder / "trials.parquet").read_bytes()
        entries = []
        for index, row in enumerate(table_row_digests(table_bytes)):
            names = [n.format(index) for n in RUN_FILES if (folder / n.format(index)).is_file()]
            entries.append(
                {"index": index, "row": row, "files": {n: file_digest(folder / n) for n in names}}
            )
        write_run(folder, root, entries, config)
    write_root(root, manifest)
    mark_sealed(root)


def stale_figures(root: Path) -> dict[str, str | None]:
    """The figure files of ``root`` (:func:`figure_files`) that were not drawn from its trials
    as they are now: name → the inputs digest its seal recorded (None: never recorded).
    ``lonlib verify --seal`` seals them so, and they stay stale until ``lonlib analyse``."""
    root = Path(root)
    seal = read_seal(root / SEAL_NAME) if is_sealed(root) else {}
    figures = seal.get("figures", {})
    ahead = figures_ahead(root, figures)
    now = inputs_now(root, seal) if seal else None
    out: dict[str, str | None] = {}
    for path in figure_files(root):
        name = path.relative_to(root).as_posix()
        drawn = drawn_from(figures, name) if name in figures.get("files", {}) else None
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
        entries, config = read_run(path)
        for entry in entries:
            ahead = {n: d for n, d in names.items() if n in entry["files"]}
            if ahead:
                entry["next"] = {**entry.get("next", {}), **ahead}
        write_run(folder, root, entries, config)


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
        entries, config = read_run(digests)
        names = {p.name: file_digest(p) for p in changed}
        for entry in entries:
            entry["files"] = {n: names.get(n, d) for n, d in entry["files"].items()}
            entry.pop("next", None)
        write_run(folder, root, entries, config)
    write_root(root, manifest)


def reseal_outputs(
    root: Path,
    *,
    figures: Iterable[Path] | None = None,
    recordings: Mapping[str, Mapping[str, Any]] | None = None,
    stale_figures: Mapping[str, str | None] | None = None,
    inputs: str | None = None,
) -> bool:
    """After ``lonlib analyse`` (``figures``: the files it wrote; its HTML pages, kept out of
    git, are left out; the earlier figures still there are kept, :func:`write_root`) or
    ``lonlib record`` (``recordings``: the index of every recording in the folder): their
    digests in the root seal, under the manifest lock. ``stale_figures``: figures not drawn
    from the trials as they are (``lonlib verify --seal``, :func:`stale_figures`).
    ``inputs``: the digest of the trials the figures were drawn from, as loaded (None: as
    sealed now). Nothing in an unsealed folder (returns False)."""
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
            figures_inputs=inputs,
        )
    return True


def seal_outputs_ahead(
    root: Path,
    *,
    figures: Mapping[str, str | None] | None = None,
    recordings: Mapping[str, Mapping[str, Any]] | None = None,
    inputs: str | None = None,
) -> bool:
    """Before ``lonlib analyse`` or ``lonlib record`` puts its outputs in place (each file
    written under a temporary name first, then renamed): ``figures`` (name relative to the
    root → the digest of its new content, None for a figure it removes; ``inputs``: the
    digest of the trials they were drawn from, as loaded, None: as sealed now) or
    ``recordings`` (the index the recordings folder will hold, each entry with its
    ``sha256``) sealed ahead in the root, under the manifest lock, so that a kill between
    two renames, or before the reseal (:func:`reseal_outputs`) that settles them, leaves
    every file accepted as sealed or as sealed ahead (pending, never tampered). What a
    killed write of the root left (``.seal.json.<random>.tmp``) is removed first. Nothing
    in an unsealed folder (returns False)."""
    from lonlib.storage.layout import MANIFEST_LOCK, read_manifest
    from lonlib.storage.lock import exclusive_lock

    root = Path(root)
    if not is_sealed(root):
        return False
    with exclusive_lock(root / MANIFEST_LOCK, record_holder=False):
        remove_temporary_files(root, SEAL_NAME)  # every write of the root holds this lock
        write_root(
            root,
            read_manifest(root),
            figures_ahead=figures,
            recordings_ahead=recordings,
            figures_inputs=inputs,
        )
    return True


def drop_unwritten_trials(run_folder: Path, root: Path) -> int:
    """Drop a run's digests entries sealed ahead of a table write that never happened (a kill
    between the two, or a failed table write): the next local search redoes that trial.
    Called by the process that takes the run (holding its lock) after the folder's seal was
    checked; nothing in an unsealed experiment. Returns the number of entries dropped."""
    root, run_folder = Path(root), Path(run_folder)
    path = run_folder / RUN_DIGESTS
    if not is_sealed(root) or not path.exists():
        return 0
    entries, config = read_run(path)
    table = run_folder / "trials.parquet"
    rows = len(table_row_digests(table.read_bytes())) if table.exists() else 0
    if len(entries) <= rows:
        return 0
    kept = entries[:rows]
    write_run(run_folder, root, kept, config)
    return len(entries) - rows


__all__ = [
    "append_trial",
    "drop_unwritten_trials",
    "mark_sealed",
    "refresh_root",
    "reseal_files",
    "reseal_outputs",
    "seal_ahead",
    "seal_outputs_ahead",
    "seal_runs",
    "settle_ahead",
    "stale_figures",
    "write_root",
]
