"""The ``lonlib`` verbs of the physics studies: ``calibrate``, ``imitate`` and ``hold-test``."""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

from lonlib.cli._common import (
    check_output_folder,
    markdown_page,
)
from lonlib.util.validation import check_range


def calibrate_verb(args: argparse.Namespace) -> None:
    """``lonlib calibrate``: run (or resume) the physics calibration study."""
    from lonlib.calibration import run_calibration
    from lonlib.calibration.report import calibration_block, readme_markers, write_outputs
    from lonlib.config import load_calibration, with_overrides
    from lonlib.util.readme_tables import splice

    config = with_overrides(load_calibration(args.grid), args.seeds, args.max_steps, args.batch)
    readme = markdown_page(args.docs)
    begin, end = readme_markers(config.name)
    if readme is not None:  # refuse a page without the markers before any work
        splice(readme.read_text(), begin, end, "")
    if args.dry_run:
        state = check_output_folder(Path(args.out))
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


def imitate_verb(args: argparse.Namespace) -> None:
    """``lonlib imitate``: the two-cart balancing Actor of the hold test, by imitation."""
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


def hold_test_verb(args: argparse.Namespace) -> None:
    """``lonlib hold-test``: run (or resume) the hold test."""
    from lonlib.calibration.hold import HoldTest, load_hold_config, plan

    check_range("--checkpoint-minutes", args.checkpoint_minutes, 0.0, 1e7)
    config = load_hold_config(args.config).with_overrides(args.seeds, args.max_steps, args.batch)
    test = HoldTest(config, args.out)
    if args.dry_run:
        state = check_output_folder(Path(args.out))
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


__all__ = [
    "calibrate_verb",
    "hold_test_verb",
    "imitate_verb",
]
