"""The checks of an experiment against its seal (:mod:`lonlib.storage.digests`): what
:func:`check_experiment_seal` finds, file by file (tampered data, or an interrupted write's
pending state), and a reader's gate (:func:`check_readable`)."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lonlib.storage._digests_format import (
    FIGURES_FOLDER,
    RECORDINGS_FOLDER,
    RUN_DIGESTS,
    SEAL_NAME,
    SEALED_FIELD,
    TRIAL_FILE,
    TamperedDataError,
    TamperedDataWarning,
    UnsealedDataWarning,
    chained,
    config_digest,
    drawn_from,
    figure_files,
    figures_ahead,
    file_digest,
    inputs_now,
    is_sealed,
    read_run,
    read_seal,
    result_path_versions,
    run_folders,
    run_key,
    table_row_digests,
)


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
    recordings and figures (differences among them alone are checked again, once, against
    the seal read again: an ``analyse`` or ``record`` may have renamed its outputs between
    the two reads)."""
    root = Path(root)
    check = SealCheck(root, is_sealed(root))
    if not check.sealed:
        _check_lost_seal(check, root, manifest, files)
        return check
    try:
        seal = read_seal(root / SEAL_NAME)
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
    folders = {run_key(f, root): f for f in run_folders(root)}
    for key in sorted(set(sealed_runs) - set(folders)):
        check.problems.append((f"{key}/trials.parquet", "a sealed run's trials table is missing"))
    for key, folder in folders.items():
        run = _SealedRun(key, folder, sealed_runs.get(key), seal.get("chain_config"))
        _check_run(check, run, files)
    outputs = _check_outputs(root, seal, figures, recordings)
    if outputs.problems and check.ok:
        # `analyse` or `record` may have sealed ahead and renamed its outputs between this
        # check's read of the seal and its read of the files: read both again, once
        try:
            again = read_seal(root / SEAL_NAME)
        except TamperedDataError:
            again = None
        if again is not None and again.get("kind") == "experiment":
            outputs = _check_outputs(root, again, figures, recordings)
    check.problems += outputs.problems
    check.pending += outputs.pending
    return check


def _check_outputs(
    root: Path, seal: Mapping[str, Any], figures: bool, recordings: bool
) -> SealCheck:
    """What the recordings (asked) and the figures (asked) show against ``seal``."""
    check = SealCheck(root, True)
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
            key = run_key(folder, root)
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
        entries, config = read_run(digests)
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
    if [e.get("chain") for e in entries] != [e["chain"] for e in chained(run.key, entries, config)]:
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
        match = TRIAL_FILE.fullmatch(path.name)
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
    ahead = figures_ahead(root, figures)  # those there as sealed ahead (or removed so)
    if "next" in figures:
        check.pending.append(
            (
                SEAL_NAME,
                "figures and tables sealed ahead of a `lonlib analyse` that stopped before it "
                "finished putting them in place: `lonlib analyse` again completes it",
            )
        )
    drawn = {name: drawn_from(figures, name) for name in listed}
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
    now = inputs_now(root, seal) if drawn else None
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


__all__ = [
    "SealCheck",
    "check_experiment_seal",
    "check_readable",
]
