"""The ``lonlib`` command: run experiments, see their status, build and export their LONs,
analyse a stored experiment (figures, tables, the paper's claims), calibrate the physics.

The verbs lie in private modules by job: the parser (``_parser``), the experiments' verbs
(``_experiments``: run, status, lon), the stored experiment's (``_analysis``: analyse, record,
verify, thin), the studies' (``_studies``: calibrate, imitate, hold-test) and what they share
(``_common``).
"""

from __future__ import annotations

import sys

from lonlib.cli._common import experiment_folder
from lonlib.cli._parser import (
    DeprecatedFlag,
    add_fitness_tolerance,
    build_parser,
    check_arguments,
)
from lonlib.storage.atomic import CorruptDataError
from lonlib.task.gymnasium_task import TaskEnvironmentError
from lonlib.util.messages import show_lonlib_messages


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``lonlib`` command."""
    args = build_parser().parse_args(argv)
    show_lonlib_messages()
    try:
        check_arguments(args)
        args.func(args)
    except (ValueError, CorruptDataError, OSError, MemoryError, TaskEnvironmentError) as error:
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


__all__ = [
    "DeprecatedFlag",
    "add_fitness_tolerance",
    "build_parser",
    "check_arguments",
    "experiment_folder",
    "main",
]
