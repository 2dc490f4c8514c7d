"""The ``lonlib`` command line: its parser (each verb and option, ``--help``) and the ranges
of the verbs' numeric options, checked before any verb runs."""

from __future__ import annotations

import argparse
import re
import sys

from lonlib.cli._analysis import analyse_verb, record_verb, thin_verb, verify_verb
from lonlib.cli._experiments import lon_verb, run_verb, status_verb
from lonlib.cli._studies import calibrate_verb, hold_test_verb, imitate_verb
from lonlib.config import EXECUTORS, NAMED_CONFIGS
from lonlib.storage.manifest import CHANGEABLE_FIELDS
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
        help="lockstep: write the batch in flight this often, to resume mid-search after a "
        "kill (at least 1; 0: never write nor resume one; default 10; a Gymnasium task's "
        "batch is not checkpointed)",
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
    run.set_defaults(func=run_verb)

    stat = sub.add_parser("status", help="what is finished, started and left")
    stat.add_argument("dir")
    stat.add_argument(
        "--runs", action="store_true", help="also one line per run: its state and fitness chain"
    )
    stat.set_defaults(func=status_verb)

    lon = sub.add_parser("lon", help="print LON metrics per p and write exports")
    lon.add_argument("dir")
    lon.add_argument("--full", action="store_true", help="add rejected trials (worsening)")
    add_fitness_tolerance(lon)
    lon.add_argument("--out", help="export folder (default DIR/lon)")
    lon.set_defaults(func=lon_verb)

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
    analysis.set_defaults(func=analyse_verb)

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
    record.set_defaults(func=record_verb)

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
    verify.set_defaults(func=verify_verb)

    thin = sub.add_parser(
        "thin",
        help="keep only the judged rows of every training history (before committing a folder)",
    )
    thin.add_argument("dir", help="experiment folder, e.g. data/one-cart")
    thin.set_defaults(func=thin_verb)

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
    calibrate.set_defaults(func=calibrate_verb)

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
    imitate.set_defaults(func=imitate_verb)

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
    hold.set_defaults(func=hold_test_verb)
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


__all__ = [
    "ARGUMENT_RANGES",
    "DESCRIPTION",
    "DeprecatedFlag",
    "EPILOG",
    "NEGATIVE_NUMBER",
    "add_fitness_tolerance",
    "build_parser",
    "check_arguments",
]
