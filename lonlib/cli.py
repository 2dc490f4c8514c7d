"""The ``lonlib`` command: run experiments, see their status, build and export their LONs,
analyse a stored experiment (figures, tables, the paper's claims), calibrate the physics."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import os
import re
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path

import pandas as pd

from lonlib.config import EXECUTORS, NAMED_CONFIGS
from lonlib.storage.atomic import CorruptDataError, DataWriteError, check_output_place
from lonlib.storage.manifest import CHANGEABLE_FIELDS
from lonlib.util.labels import p_label
from lonlib.util.messages import show_lonlib_messages
from lonlib.util.validation import check_range

# `lonlib --help`, plain text (no markup: the terminal shows it as it is written).
DESCRIPTION = """\
Local Optima Networks of DDPG on the coupled inverted pendulums task: sample them by basin
hopping (run), follow and analyse them (status, lon, analyse, record, verify), thin their
training histories before committing them (thin), calibrate the physics (calibrate).
Run 'lonlib VERB --help' for a verb's options.

Every verb takes --dry-run: check the arguments, the configuration, the executor and the
folders, then stop before any compute or write.
"""
EPILOG = """\
exit status: 0 done; 1 'lonlib verify' found a mismatch; 2 an error (a message on stderr
starting 'lonlib: error:' or, for a malformed command line, 'lonlib <verb>: error:').
Documentation: docs/ (make docs builds the site into site/)."""

# A number such as -1e-4 is a value, not an option (argparse's own pattern misses exponents).
NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


class _Parser(argparse.ArgumentParser):
    """argparse's parser that reads ``-1e-4`` as a number (so ``--p -1e-4`` reaches the
    configuration's own check, which refuses it by name), for the parser and its verbs."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER


def experiment_folder(text: str) -> Path:
    """``text`` as a folder that exists: ValueError saying "no such folder" or "not a folder"
    otherwise (whether it holds an experiment is the reader's check)."""
    path = Path(text)
    if not path.exists():
        raise ValueError(f"{path}: no such folder")
    if not path.is_dir():
        raise ValueError(f"{path}: not a folder (it is a file); give an experiment's folder")
    return path


def _markdown_page(text: str | None) -> Path | None:
    """The Markdown page of ``--docs`` (or ``None``): ValueError if it is missing."""
    if text is None:
        return None
    page = Path(text)
    if page.is_dir():
        raise ValueError(f"--docs {page}: is a folder, not a file")
    if not page.is_file():
        raise ValueError(f"--docs {page}: no such file")
    return page


def _check_output_folder(out: Path) -> str:
    """What ``lonlib run`` checks of its output folder before computing, without creating or
    writing anything: the parent exists, ``out`` is not a file and, if it exists, is
    writable. Returns "new" or "exists"."""
    check_output_place(out)
    if out.exists() and not os.access(out, os.W_OK | os.X_OK):
        raise DataWriteError(13, f"cannot write {out}: permission denied")
    return "exists" if out.exists() else "new"


def _run(args: argparse.Namespace) -> None:
    from lonlib.config import load_config
    from lonlib.experiment.running import pending_runs, run_experiment

    config = load_config(args.config)
    changes: dict = {}
    if args.p:
        changes["perturbations"] = tuple(args.p)
    if args.runs is not None:
        changes["runs"] = args.runs
    if args.device:
        changes["ddpg"] = dataclasses.replace(config.ddpg, device=args.device)
    if changes:
        config = dataclasses.replace(config, **changes)  # validated again on construction
    out = Path(args.out) if args.out else Path("data") / config.name
    if args.checkpoint_minutes != 0:  # a write takes ~11 MB per slot: not every few steps
        check_range("checkpoint_minutes (0 for never)", args.checkpoint_minutes, 1.0, 1e7)
    if args.dry_run:
        _dry_run_experiment(config, out, args)
        return
    trials = run_experiment(
        config,
        out,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not args.quiet,
        executor=args.executor,
        slots=args.slots,
        checkpoint_seconds=args.checkpoint_minutes * 60 if args.checkpoint_minutes else None,
        drain_after_seconds=None if args.drain_after is None else args.drain_after * 60,
        allow_changes=args.allow_change or (),
    )
    print(f"{len(trials)} local searches stored under {out}")
    if args.drain_after is not None:
        left = len(pending_runs(config, out))
        total = len(config.perturbations) * config.runs
        print(
            f"{left} of {total} runs unfinished: run the same command again to continue them"
            if left
            else f"all {total} runs finished"
        )


def _task_words(config) -> str:
    """`` (Gymnasium task Pendulum-v1, local search ddpg)`` for a Gymnasium task, else ""."""
    if config.task is None:
        return ""
    return f" (Gymnasium task {config.task.gymnasium}, local search {config.task.search})"


def _dry_run_experiment(config, out: Path, args: argparse.Namespace) -> None:
    """``lonlib run --dry-run``: every check ``run_experiment`` makes before computing
    (configuration, executor, slots, device, lockstep batch, output folder, a stored
    experiment's configuration), nothing computed, created or written."""
    from lonlib.ddpg import check_device
    from lonlib.experiment.admission import (
        check_memory,
        concurrent_searches,
        search_memory_bytes,
        task_sizes,
    )
    from lonlib.experiment.executors import resolve_executor, session_executor
    from lonlib.experiment.lockstep import check_drain, check_lockstep
    from lonlib.sb3 import check_search
    from lonlib.storage.digests import check_readable
    from lonlib.storage.layout import read_manifest
    from lonlib.storage.manifest import manifest_path, updated_manifest

    kind = resolve_executor(
        session_executor(args.executor, config.executor, args.scheduler),
        args.workers,
        args.scheduler,
    )
    slots = config.slots if args.slots is None else args.slots
    check_range("slots", slots, 1, 100_000)
    check_device(config.ddpg.device)
    if config.task is not None:
        check_search(config.task.search, config.ddpg.device)
    if kind == "lockstep":
        check_lockstep(config.ddpg, slots)
    check_drain(kind, None if args.drain_after is None else args.drain_after * 60)
    sized = dataclasses.replace(config, slots=slots)
    searches = concurrent_searches(sized, kind, args.workers, args.scheduler)
    check_memory(sized, searches)
    state = _check_output_folder(out)
    if state == "exists" and manifest_path(out).exists():
        check_readable(out, read_manifest(out), "lonlib run")  # what a resume checks first
        manifest = updated_manifest(
            dataclasses.replace(config, executor=kind, slots=slots),
            out,
            allow_changes=args.allow_change or (),
        )
        state = "resumes the experiment stored there" + "".join(
            f", changing {key} from {old} to {new}"
            for key, (old, new) in manifest["sessions"][-1].get("changed", {}).items()
        )
    elif state == "exists":
        state = "an empty experiment folder"
    else:
        state = "created by the run"
    where = f"{kind}, {args.workers} worker(s)"
    if args.scheduler:
        where += f" on {args.scheduler}"
    if kind == "lockstep":
        where += f", {slots} slots on {config.ddpg.device}"
    if args.drain_after is not None:
        where += f", draining after {args.drain_after:g} minutes"
    need = searches * search_memory_bytes(task_sizes(config), config.ddpg) / 2**30
    where += f"; about {need:.2g} GiB for {searches} search(es) at once"
    print(
        f"dry run: {config.name}{_task_words(config)}: "
        f"p {', '.join(f'{p:g}' for p in config.perturbations)}, "
        f"{config.runs} runs per p; executor {where}; output {out} ({state}). "
        "Nothing computed or written."
    )


def _dry_run_reader(verb: str, root: Path) -> None:
    """``--dry-run`` of a verb that reads an experiment: the folder holds one, and (but for
    verify) its data match their seal."""
    from lonlib.storage.digests import check_readable
    from lonlib.storage.layout import read_manifest

    manifest = read_manifest(root)
    if verb != "verify":  # a reader refuses changed data (status says so); verify reports it
        reads = verb != "status"  # status reads the tables, not every trial's files
        check_readable(root, manifest, f"lonlib {verb}", refuse=reads, files=reads)
    name = manifest["config"].get("name", "?")
    print(f"dry run: lonlib {verb} would read the experiment {name!r} in {root}. Nothing done.")


def _status(args: argparse.Namespace) -> None:
    from lonlib.experiment.running import status
    from lonlib.storage.status import run_status

    root = experiment_folder(args.dir)
    with _seal_warnings_as_lines():
        if args.dry_run:
            return _dry_run_reader("status", root)
        table = status(args.dir)
        runs = run_status(args.dir) if args.runs else None
    print(table.to_string(index=False))
    print(_sessions_line(root))
    if runs is not None:
        with pd.option_context("display.width", 250, "display.max_colwidth", 160):
            print(runs.to_string(index=False))
    return None


@contextlib.contextmanager
def _seal_warnings_as_lines() -> Iterator[None]:
    """Say what the seal check of a reader that only reports (``lonlib status``) found as
    ``lonlib: warning: ...`` lines on stderr, each once; other warnings as Python shows them."""
    from lonlib.storage.digests import TamperedDataWarning, UnsealedDataWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    said = set()
    for warning in caught:
        if not issubclass(warning.category, (TamperedDataWarning, UnsealedDataWarning)):
            warnings.showwarning(
                warning.message, warning.category, warning.filename, warning.lineno
            )
        elif str(warning.message) not in said:
            said.add(str(warning.message))
            print(f"lonlib: warning: {warning.message}", file=sys.stderr)


def _sessions_line(root: Path) -> str:
    """How many sessions sampled the experiment and the time they recorded, summed."""
    from lonlib.storage import session_seconds

    seconds, sessions, missing = session_seconds(root)
    line = f"{sessions} sessions; {seconds / 3600:.2f} h of sampling time recorded, summed"
    if missing:
        line += (
            f" ({missing} without an end: running, killed, stopped by a failed write, or "
            "sampled before lonlib recorded session ends)"
        )
    return line


def _lon(args: argparse.Namespace) -> None:
    from lonlib.lon.graphs import build_lon, cmlon
    from lonlib.lon.io import to_graphml, to_trace
    from lonlib.lon.metrics import metrics_table
    from lonlib.storage.trials import read_finished_trials

    root = experiment_folder(args.dir)
    if args.dry_run:
        return _dry_run_reader("lon", root)
    trials = read_finished_trials(root, reader="lonlib lon")
    table = metrics_table(trials, "max", args.fitness_tolerance)
    with pd.option_context("display.width", 200, "display.max_columns", 30):
        print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    out = Path(args.out) if args.out else root / "lon"
    out.mkdir(parents=True, exist_ok=True)
    table.to_csv(out / "metrics.csv", index=False)
    for p, group in trials.groupby("p"):
        graph = build_lon(group, "max", args.fitness_tolerance, full=args.full)
        stem = f"lon_p={p_label(p)}" + ("_full" if args.full else "")
        to_graphml(graph, out / f"{stem}.graphml")
        to_trace(graph, out / f"{stem}.trace")
        to_graphml(cmlon(graph), out / f"cmlon_p={p_label(p)}.graphml")
    print(f"metrics, GraphML and trace files written to {out}")


def _analyse(args: argparse.Namespace) -> None:
    from lonlib.analysis.claims_report import claims_markdown, splice_readme
    from lonlib.analysis.claims_rescored import side_by_side_markdown, splice_side_by_side
    from lonlib.analysis.holding import holding_markdown, holding_summary, splice_holding
    from lonlib.analysis.pipeline import analyse
    from lonlib.analysis.summary import splice_summary, summary_markdown

    root = experiment_folder(args.dir)
    readme = _markdown_page(args.docs)
    if readme is not None:  # refuse a page without the markers before any work
        text = splice_summary(splice_readme(readme.read_text(), "", args.dir), "", args.dir)
        splice_holding(text, "", args.dir)
    if args.dry_run:
        return _dry_run_reader("analyse", root)
    result = analyse(
        args.dir,
        seed=args.seed,
        fitness_tolerance=args.fitness_tolerance,
        bins=args.bins,
        close_figures=True,
    )
    with pd.option_context("display.width", 200, "display.max_colwidth", 120):
        print(result.summary.drop(columns="behaviours", errors="ignore").to_string(index=False))
        if not result.claims.empty:
            print(result.claims[["claim", "verdict", "evidence"]].to_string(index=False))
    if result.skipped:
        print(result.skipped)
    print(f"{len(result.files)} figures and tables written to {Path(args.dir) / 'figures'}")
    if readme is not None:
        text = splice_readme(
            readme.read_text(),
            claims_markdown(result.claims, result.claim_peaks, result.power, result.claim_d_curve),
            args.dir,
        )
        text = splice_summary(text, summary_markdown(result.summary), args.dir)
        side = result.claims_side_by_side
        text = splice_side_by_side(
            text, side_by_side_markdown(side) if not side.empty else "", args.dir
        )
        holding = holding_markdown(holding_summary(result.holding))
        text = splice_holding(text, holding, args.dir)
        readme.write_text(text, encoding="utf-8")
        print(f"summary and claims tables pasted into {readme}")
    return None


def _record(args: argparse.Namespace) -> None:
    from lonlib.analysis.pipeline import record_optima

    root = experiment_folder(args.dir)
    if args.dry_run:
        return _dry_run_reader("record", root)
    paths = record_optima(args.dir, bins=args.bins, limit=args.limit)
    for path in paths:
        print(path)
    print(f"{len(paths)} recordings written under {args.dir}/recordings/")
    return None


def _verify(args: argparse.Namespace) -> None:
    from lonlib.analysis.verify import verify_experiment
    from lonlib.storage.layout import read_manifest

    root = experiment_folder(args.dir)
    if args.dry_run:
        return _dry_run_reader("verify", root)
    if not (root / "manifest.json").exists() and (args.seal or (root / "seal.json").exists()):
        return _verify_files(root, args.seal)
    report = verify_experiment(args.dir, recordings=not args.no_recordings)
    shown = report.findings if args.all else report.findings[: args.limit]
    for finding in shown:
        print(finding)
    if len(shown) < len(report.findings):
        print(f"... {len(report.findings) - len(shown)} more (--all shows every finding)")
    print(report.summary())
    failed = not report.ok
    if args.seal:  # --seal completes its own interrupted seal: that finding does not stop it
        from lonlib.analysis.verify import blocks_sealing

        failed = blocks_sealing(report)
        if failed and report.ok:
            print(
                "not sealed: stored numbers do not replay (reported as warnings: another "
                "result-path version); only a folder whose numbers replay is sealed"
            )
    if args.gymnasium and (read_manifest(root).get("config") or {}).get("task") is not None:
        print(
            "info: [gymnasium] --gymnasium replays the coupled pendulums' registered "
            "environment only; a Gymnasium task's replay above already goes through "
            "gymnasium.make (plain verify): nothing more to replay"
        )
    elif args.gymnasium:
        from lonlib.storage.policies import gymnasium_mismatches

        replayed, mismatches = gymnasium_mismatches(root)
        for line in mismatches[: len(mismatches) if args.all else args.limit]:
            print(f"[gymnasium] {line}")
        print(
            f"gymnasium: {replayed - len(mismatches)} of {replayed} accepted optima replay "
            "their stored fitness through gymnasium.make (float64 observations)"
        )
        failed = failed or bool(mismatches)
    if failed:
        raise SystemExit(1)
    if args.seal:
        from lonlib.analysis.verify import seal_experiment

        seal_experiment(report)
        print(f"sealed: {root / 'seal.json'} and each run's digests.json")
    return None


def _verify_files(root: Path, seal: bool) -> None:
    """``lonlib verify`` of a folder that is not an experiment (a study's summaries): its
    files against its ``files`` seal, then (``--seal``) sealed as they are, never silently:
    a folder whose files differ from their seal is refused (to accept a deliberate change,
    delete its ``seal.json`` first); files written since the seal (pending) are sealed."""
    from lonlib.storage.digests import check_files_seal, seal_files

    check = check_files_seal(root)
    for name, what in check.problems:
        print(f"error: [digest] {name}: {what}")
    for name, what in check.pending:
        print(f"warning: [digest] {name}: {what}")
    print("verify: OK" if check.ok else f"verify: FAILED ({len(check.problems)} errors)")
    if not check.ok:
        if seal:
            print(
                f"not sealed: files differ from their seal; to accept a deliberate change, "
                f"delete {root / 'seal.json'}, then `lonlib verify {root} --seal`"
            )
        raise SystemExit(1)
    if seal:
        print(f"sealed {seal_files(root)} files: {root / 'seal.json'}")


def _thin(args: argparse.Namespace) -> None:
    from lonlib.storage.thin import thin_histories

    report = thin_histories(experiment_folder(args.dir), dry_run=args.dry_run)
    print(("would thin " if args.dry_run else "thinned ") + report.summary())


def _calibrate(args: argparse.Namespace) -> None:
    from lonlib.calibration import run_calibration
    from lonlib.calibration.report import calibration_block, readme_markers, write_outputs
    from lonlib.config import load_calibration, with_overrides
    from lonlib.util.readme_tables import splice

    config = with_overrides(load_calibration(args.grid), args.seeds, args.max_steps, args.batch)
    readme = _markdown_page(args.docs)
    begin, end = readme_markers(config.name)
    if readme is not None:  # refuse a page without the markers before any work
        splice(readme.read_text(), begin, end, "")
    if args.dry_run:
        state = _check_output_folder(Path(args.out))
        print(
            f"dry run: calibration grid {config.name!r}: {len(config.cells)} cells x "
            f"{config.seeds} seeds x {config.max_steps} env steps; output {args.out} ({state}). "
            "Nothing computed or written."
        )
        return
    if args.stored_only:
        result = write_outputs(config, args.out, stored_only=True)
    else:
        result = run_calibration(config, args.out, workers=args.workers, progress=not args.quiet)
    if readme is not None:
        body = calibration_block(
            args.out, (Path(args.out) / "calibration.md").read_text(), config.name
        )
        readme.write_text(splice(readme.read_text(), begin, end, body))
        print(f"calibration table pasted into {readme}")
    with pd.option_context("display.width", 200, "display.max_columns", 30):
        print(result.cells.drop(columns=["seconds"]).to_string(index=False))
        print(result.drift.to_string(index=False))
    print(f"tables and figure written to {args.out}")


def _imitate(args: argparse.Namespace) -> None:
    from lonlib.calibration.imitation import ImitationConfig, imitate, write_imitation

    values = {"seed": args.seed}
    for name in ("teacher", "rounds", "updates"):
        if getattr(args, name) is not None:
            values[name] = getattr(args, name)
    config = ImitationConfig(**values)
    if args.dry_run:
        print(
            f"dry run: imitation of {config.teacher} (seed {config.seed}, {config.rounds} "
            f"DAgger rounds) into {args.out}. Nothing computed or written."
        )
        return
    result = imitate(config, progress=not args.quiet)
    path = write_imitation(args.out, result, config)
    print(f"two-cart Actor of round {result.round} scores {result.fitness:.4f}; written to {path}")


def _hold_test(args: argparse.Namespace) -> None:
    from lonlib.calibration.hold import HoldTest, load_hold_config, plan

    check_range("--checkpoint-minutes", args.checkpoint_minutes, 0.0, 1e7)
    config = load_hold_config(args.config).with_overrides(args.seeds, args.max_steps, args.batch)
    test = HoldTest(config, args.out)
    if args.dry_run:
        state = _check_output_folder(Path(args.out))
        print(
            f"dry run: hold test, {len(plan(config))} searches ({', '.join(config.arms)} x "
            f"p {', '.join(f'{p:g}' for p in config.perturbations)} x {config.seeds} seeds, "
            f"<= {config.ddpg.max_steps} env steps each); output {args.out} ({state}). "
            "Nothing computed or written."
        )
        return
    summary, done = test.run(
        drain_after_seconds=None if args.drain_after is None else args.drain_after * 60,
        checkpoint_seconds=args.checkpoint_minutes * 60,
        progress=not args.quiet,
    )
    with pd.option_context("display.width", 200, "display.max_columns", 30):
        print(summary.to_string(index=False))
    print(
        f"hold test {'finished' if done else 'not finished (run the same command to continue)'}"
        f"; tables in {args.out}"
    )


class DeprecatedFlag(argparse.Action):
    """An option's old spelling: stores to the new one and says so on stderr."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        """Store ``values`` under the new name and print the new spelling."""
        print(
            f"lonlib: {option_string} is deprecated, use --{self.dest.replace('_', '-')}",
            file=sys.stderr,
        )
        setattr(namespace, self.dest, values)


def add_fitness_tolerance(parser: argparse.ArgumentParser) -> None:
    """``--fitness-tolerance``: two fitness values closer than this are equal in the LON (the
    old spelling ``--tolerance`` still works; tolerance alone is Algorithm 2's T)."""
    parser.add_argument(
        "--fitness-tolerance", type=float, default=1e-9, help="fitness equality in the LON"
    )
    parser.add_argument(
        "--tolerance",
        type=float,
        dest="fitness_tolerance",
        action=DeprecatedFlag,
        help=argparse.SUPPRESS,
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``lonlib`` (also used for ``--help``)."""
    parser = _Parser(
        prog="lonlib",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="VERB")

    run = sub.add_parser("run", help="run (or resume) an experiment")
    run.add_argument("config", help=f"one of {', '.join(NAMED_CONFIGS)}, or a YAML file")
    run.add_argument("--p", type=float, nargs="+", help="perturbation strengths (override)")
    run.add_argument("--runs", type=int, help="runs per p (override)")
    run.add_argument("--workers", type=int, default=1, help="local worker processes")
    run.add_argument("--scheduler", help="Dask scheduler address, or 'dask-local'")
    run.add_argument(
        "--executor",
        choices=EXECUTORS,
        help="where runs execute (default: the configuration's, 'auto': Dask with a "
        "scheduler, a pool with --workers > 1, else serial; 'lockstep': the local searches "
        "of many runs trained as one batch in this process)",
    )
    run.add_argument("--slots", type=int, help="local searches per lockstep batch")
    run.add_argument("--device", help="torch device of DDPG, e.g. 'cpu' or 'cuda'")
    run.add_argument(
        "--checkpoint-minutes",
        type=float,
        default=10.0,
        help="lockstep: write the batch in flight this often, to resume mid-search after a "
        "kill (at least 1; 0: never write nor resume one; default 10)",
    )
    run.add_argument(
        "--drain-after",
        type=float,
        metavar="MINUTES",
        help="lockstep: after this many minutes start no new local search, finish and store "
        "those in flight, and exit; the same command again continues (for a machine whose "
        "time runs out; 0: one search per slot)",
    )
    run.add_argument(
        "--allow-change",
        action="append",
        choices=CHANGEABLE_FIELDS,
        metavar="FIELD",
        help="let a stored experiment take this setting from the configuration (only "
        "max_local_searches: a lower cap ends the runs that reach it, a higher one continues "
        "the runs the old cap ended, not those T ended); refused if a stored run has more "
        "local searches than the new cap; recorded in the manifest",
    )
    run.add_argument("--out", help="output folder (default data/<name>)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.set_defaults(func=_run)

    stat = sub.add_parser("status", help="what is finished, started and left")
    stat.add_argument("dir")
    stat.add_argument(
        "--runs", action="store_true", help="also one line per run: its state and fitness chain"
    )
    stat.set_defaults(func=_status)

    lon = sub.add_parser("lon", help="print LON metrics per p and write exports")
    lon.add_argument("dir")
    lon.add_argument("--full", action="store_true", help="add rejected trials (worsening)")
    add_fitness_tolerance(lon)
    lon.add_argument("--out", help="export folder (default DIR/lon)")
    lon.set_defaults(func=_lon)

    analysis = sub.add_parser(
        "analyse",
        help="figures, tables and the paper's claims from a stored experiment (no sampling)",
    )
    analysis.add_argument("dir", help="experiment folder, e.g. data/reference")
    analysis.add_argument("--seed", type=int, default=0, help="layout seed of the 3-D LON")
    add_fitness_tolerance(analysis)
    analysis.add_argument("--bins", type=int, default=50, help="histogram bins on [0, 1]")
    analysis.add_argument(
        "--docs",
        "--readme",
        metavar="PAGE",
        help="also paste the summary and claims tables between their markers in this Markdown "
        "page, and the optima that hold their rods where it has the holding markers "
        "(docs/results.md; --readme is the former name)",
    )
    analysis.set_defaults(func=_analyse)

    record = sub.add_parser(
        "record",
        help="rerun recordings of the best optima, the sinks at the peaks and the best of each "
        "behaviour, replayed from their stored Actors",
    )
    record.add_argument("dir", help="experiment folder, e.g. data/reference")
    record.add_argument("--bins", type=int, default=50, help="histogram bins of the peaks")
    record.add_argument(
        "--limit", type=int, default=24, help="at most this many recordings (0: all; default 24)"
    )
    record.set_defaults(func=_record)

    verify = sub.add_parser(
        "verify",
        help="replay every stored trial and recording from its stored Actor and check each "
        "run's Algorithm 2 bookkeeping; exit 1 on a mismatch",
    )
    verify.add_argument("dir", help="experiment folder, e.g. data/reference")
    verify.add_argument("--no-recordings", action="store_true", help="skip the recordings")
    verify.add_argument(
        "--limit", type=int, default=20, help="findings printed (0: none; default 20)"
    )
    verify.add_argument("--all", action="store_true", help="print every finding")
    verify.add_argument(
        "--gymnasium",
        action="store_true",
        help="also replay every accepted optimum through gymnasium.make (float64 "
        "observations, lonlib.storage.load_policy) and require its stored fitness",
    )
    verify.add_argument(
        "--seal",
        action="store_true",
        help="after a verification that holds, seal the folder as it is (seal.json, each run's "
        "digests.json): for a folder written before digests; a folder that is not an "
        "experiment (a study's summaries) gets each kept file's digest",
    )
    verify.set_defaults(func=_verify)

    thin = sub.add_parser(
        "thin",
        help="keep only the judged rows of every training history (before committing a folder)",
    )
    thin.add_argument("dir", help="experiment folder, e.g. data/one-cart")
    thin.set_defaults(func=_thin)

    calibrate = sub.add_parser(
        "calibrate", help="run (or resume) the physics calibration study into OUT"
    )
    calibrate.add_argument("out", metavar="OUT", help="output folder")
    calibrate.add_argument(
        "--grid", default="default", help="'default', 'tiny' or a YAML file (default: default)"
    )
    calibrate.add_argument("--workers", type=int, default=1, help="cells run in parallel")
    calibrate.add_argument("--seeds", type=int, help="searches per cell (override)")
    calibrate.add_argument("--max-steps", type=int, help="env steps per search (override)")
    calibrate.add_argument("--batch", type=int, help="DDPG minibatch size (override)")
    calibrate.add_argument("--quiet", action="store_true", help="no progress bar")
    calibrate.add_argument(
        "--docs",
        "--readme",
        metavar="PAGE",
        help="also paste the cell table between the grid's calibration markers of this Markdown "
        "page (docs/calibration.md; --readme is the former name)",
    )
    calibrate.add_argument(
        "--stored-only",
        action="store_true",
        help="train nothing: write the tables, figures and --docs table of the cells stored "
        "so far (at least one), naming the cells not finished yet",
    )
    calibrate.set_defaults(func=_calibrate)

    imitate = sub.add_parser(
        "imitate",
        help="build the two-cart balancing Actor of the hold test by imitation (DAgger) of a "
        "one-cart optimum copied to both carts, into OUT (actor.npy, actor.json)",
    )
    imitate.add_argument("out", metavar="OUT", help="output folder")
    imitate.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    imitate.add_argument("--teacher", help="one-cart optimum .npz (default: the committed one)")
    imitate.add_argument("--rounds", type=int, help="DAgger rounds (override)")
    imitate.add_argument("--updates", type=int, help="Adam steps per round (override)")
    imitate.add_argument("--quiet", action="store_true", help="no progress lines")
    imitate.set_defaults(func=_imitate)

    hold = sub.add_parser(
        "hold-test",
        help="run (or resume) the hold test into OUT: DDPG local searches from a balancing "
        "Actor perturbed at each p, three arms (docs/study-geometry.md)",
    )
    hold.add_argument("out", metavar="OUT", help="output folder")
    hold.add_argument("--config", help="YAML file of hold-test settings (default: the built-in)")
    hold.add_argument("--seeds", type=int, help="seeds per arm and p (override)")
    hold.add_argument("--max-steps", type=int, help="env steps per search at most (override)")
    hold.add_argument("--batch", type=int, help="DDPG minibatch size (override)")
    hold.add_argument(
        "--checkpoint-minutes",
        type=float,
        default=10.0,
        help="write the search in flight this often, to resume mid-search after a kill "
        "(0: never; default 10)",
    )
    hold.add_argument(
        "--drain-after",
        type=float,
        metavar="MINUTES",
        help="after this many minutes start no new search, finish and store the one in "
        "flight, and exit; the same command again continues",
    )
    hold.add_argument("--quiet", action="store_true", help="no progress lines")
    hold.set_defaults(func=_hold_test)
    for name, verb in sub.choices.items():
        verb.add_argument(
            "--dry-run",
            action="store_true",
            help=(
                "read the histories and say what thinning would drop; write nothing"
                if name == "thin"
                else "check the arguments, configuration, executor and folders; compute and "
                "write nothing"
            ),
        )
    return parser


# The ranges of the verbs' numeric options, checked once before any verb runs, so that
# --dry-run refuses what the real run refuses: (option, low, high) with None for no bound.
ARGUMENT_RANGES = (
    ("fitness_tolerance", 0.0, None),
    ("bins", 1, None),
    ("workers", 1, 4096),
    ("limit", 0, None),
    ("drain_after", 0.0, 1e7),  # minutes
)


def check_arguments(args: argparse.Namespace) -> None:
    """The numeric options a verb has (:data:`ARGUMENT_RANGES`) are in range: ValueError
    naming the option otherwise."""
    for name, low, high in ARGUMENT_RANGES:
        value = getattr(args, name, None)
        if value is not None:
            check_range(f"--{name.replace('_', '-')}", value, low, high)


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``lonlib`` command."""
    args = build_parser().parse_args(argv)
    show_lonlib_messages()
    try:
        check_arguments(args)
        args.func(args)
    except (ValueError, CorruptDataError, OSError, MemoryError) as error:
        print(f"lonlib: error: {_error_message(error)}", file=sys.stderr)
        raise SystemExit(2) from None


def _error_message(error: Exception) -> str:
    """What ``lonlib: error:`` says of ``error``: an OSError without its "[Errno N]" prefix,
    naming its file when it has one."""
    if not isinstance(error, OSError) or error.strerror is None:
        return str(error)
    if error.filename is not None:
        return f"{error.filename}: {error.strerror}"
    return error.strerror


if __name__ == "__main__":
    main()
