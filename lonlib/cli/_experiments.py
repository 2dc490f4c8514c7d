"""The ``lonlib`` verbs that sample and follow experiments: ``run`` (with its ``--dry-run``),
``status`` and ``lon``."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path

import pandas as pd

from lonlib.cli._common import (
    check_output_folder,
    dry_run_reader,
    experiment_folder,
)
from lonlib.util.labels import p_label
from lonlib.util.validation import check_range


def run_verb(args: argparse.Namespace) -> None:
    """``lonlib run``: run (or resume) an experiment."""
    from lonlib.config import load_config
    from lonlib.experiment.lockstep import CHECKPOINT_SECONDS
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
    minutes = args.checkpoint_minutes
    if minutes is None:
        minutes = CHECKPOINT_SECONDS / 60
    if minutes != 0:  # a write takes ~11 MB per slot: not every few steps
        check_range("checkpoint_minutes (0 for never)", minutes, 1.0, 1e7)
    if args.checkpoint_minutes is not None and config.task is not None:
        print(
            "lonlib: warning: --checkpoint-minutes does not apply to a Gymnasium task: its "
            "lockstep batch is not checkpointed (an interrupted search re-runs from its start)",
            file=sys.stderr,
        )
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
        checkpoint_seconds=minutes * 60 if minutes else None,
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
    from lonlib.experiment.runs import check_task_descriptor
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
    # what the session uses, checked as the run checks it (lockstep refuses an SB3 search)
    config = dataclasses.replace(config, executor=kind, slots=slots)
    check_device(config.ddpg.device)
    if config.task is not None:
        check_search(config.task.search, config.ddpg.device)
    if kind == "lockstep":
        check_lockstep(config.ddpg, slots)
    check_drain(kind, None if args.drain_after is None else args.drain_after * 60)
    searches = concurrent_searches(config, kind, args.workers, args.scheduler)
    check_memory(config, searches)
    check_task_descriptor(config, out)
    state = check_output_folder(out)
    if state == "exists" and manifest_path(out).exists():
        check_readable(out, read_manifest(out), "lonlib run")  # what a resume checks first
        manifest = updated_manifest(config, out, allow_changes=args.allow_change or ())
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


def status_verb(args: argparse.Namespace) -> None:
    """``lonlib status``: what is finished, started and left."""
    from lonlib.experiment.running import status
    from lonlib.storage.status import run_status

    root = experiment_folder(args.dir)
    with _seal_warnings_as_lines():
        if args.dry_run:
            return dry_run_reader("status", root)
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


def lon_verb(args: argparse.Namespace) -> None:
    """``lonlib lon``: LON metrics per p, and the GraphML and trace exports."""
    from lonlib.lon.graphs import build_lon, cmlon
    from lonlib.lon.io import to_graphml, to_trace
    from lonlib.lon.metrics import metrics_table
    from lonlib.storage.trials import read_finished_trials

    root = experiment_folder(args.dir)
    if args.dry_run:
        return dry_run_reader("lon", root)
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


__all__ = [
    "lon_verb",
    "run_verb",
    "status_verb",
]
