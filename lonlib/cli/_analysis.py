"""The ``lonlib`` verbs that read a stored experiment and write what it shows: ``analyse``,
``record``, ``verify`` (a study folder's too) and ``thin``."""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

from lonlib.cli._common import (
    dry_run_reader,
    experiment_folder,
    markdown_page,
)


def analyse_verb(args: argparse.Namespace) -> None:
    """``lonlib analyse``: figures, tables and the paper's claims of a stored experiment
    (and ``--docs``: its tables pasted into a Markdown page)."""
    from lonlib.analysis.claims_report import claims_markdown, splice_readme
    from lonlib.analysis.claims_rescored import side_by_side_markdown, splice_side_by_side
    from lonlib.analysis.holding import holding_markdown, holding_summary, splice_holding
    from lonlib.analysis.pipeline import analyse
    from lonlib.analysis.summary import splice_summary, summary_markdown

    root = experiment_folder(args.dir)
    readme = markdown_page(args.docs)
    if readme is not None:  # refuse a page without the markers before any work
        text = splice_summary(splice_readme(readme.read_text(), "", args.dir), "", args.dir)
        splice_holding(text, "", args.dir)
    if args.dry_run:
        return dry_run_reader("analyse", root)
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


def record_verb(args: argparse.Namespace) -> None:
    """``lonlib record``: rerun recordings of the selected optima."""
    from lonlib.analysis.pipeline import record_optima

    root = experiment_folder(args.dir)
    if args.dry_run:
        return dry_run_reader("record", root)
    paths = record_optima(args.dir, bins=args.bins, limit=args.limit)
    for path in paths:
        print(path)
    print(f"{len(paths)} recordings written under {args.dir}/recordings/")
    return None


def verify_verb(args: argparse.Namespace) -> None:
    """``lonlib verify``: every stored number replayed, every digest checked (``--seal``:
    sealed after a verification that holds); exit 1 on a mismatch, or when a stored number
    could not be replayed (a task's descriptor that does not import here)."""
    from lonlib.analysis.verify import verify_experiment
    from lonlib.storage.layout import read_manifest

    root = experiment_folder(args.dir)
    if args.dry_run:
        return dry_run_reader("verify", root)
    if not (root / "manifest.json").exists() and (args.seal or (root / "seal.json").exists()):
        return _verify_files(root, args.seal)
    report = verify_experiment(args.dir, recordings=not args.no_recordings)
    shown = report.findings if args.all else report.findings[: args.limit]
    for finding in shown:
        print(finding)
    if len(shown) < len(report.findings):
        print(f"... {len(report.findings) - len(shown)} more (--all shows every finding)")
    print(report.summary())
    failed = not (report.ok and report.complete)
    if args.seal:  # --seal completes its own interrupted seal: that finding does not stop it
        from lonlib.analysis.verify import blocks_sealing

        failed = blocks_sealing(report)
        if failed and report.ok and report.complete:  # (incomplete: the summary says so)
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
    if args.seal and _outputs_pending(root):
        raise ValueError(
            f"not sealed: {root} holds figures or recordings an interrupted `lonlib analyse` "
            "or `record` left part-way (sealed ahead); run that command again first, then seal"
        )
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


def thin_verb(args: argparse.Namespace) -> None:
    """``lonlib thin``: keep only the judged rows of every training history."""
    from lonlib.storage.thin import thin_histories

    report = thin_histories(experiment_folder(args.dir), dry_run=args.dry_run)
    print(("would thin " if args.dry_run else "thinned ") + report.summary())


__all__ = [
    "analyse_verb",
    "record_verb",
    "thin_verb",
    "verify_verb",
]


def _outputs_pending(root: Path) -> bool:
    """Does the folder's seal hold outputs sealed ahead (``figures.next``,
    ``recordings_next``) that an interrupted analyse or record has not put in place?"""
    import json

    path = root / "seal.json"
    if not path.is_file():
        return False
    try:
        seal = json.loads(path.read_text())
    except ValueError:
        return False  # the seal check reports it
    figures = seal.get("figures") if isinstance(seal, dict) else None
    return bool((isinstance(figures, dict) and figures.get("next")) or seal.get("recordings_next"))
