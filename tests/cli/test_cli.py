"""The ``lonlib`` command line as a user meets it: plain-text help, negative numbers, missing
folders and files said as such, one error style and exit status across verbs, a scheduler
that chooses the Dask executor, and ``--dry-run``."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from lonlib.cli import build_parser, main
from lonlib.config import load_config
from lonlib.experiment.running import run_experiment
from lonlib.storage.atomic import DataWriteError

READERS = ["status", "lon", "analyse", "record", "verify", "thin"]
# What reStructuredText or Sphinx markup looks like in a help text.
DEPRECATED = "lonlib: --tolerance is deprecated, use --fitness-tolerance"
MARKUP = re.compile(r"``|:(func|class|mod|data|meth):`")


def _fails(argv: list[str], capsys) -> str:
    """Run ``lonlib argv``; it must exit 2. Returns what it wrote on stderr."""
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    return capsys.readouterr().err


def _help(argv: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as stop:
        main([*argv, "--help"])
    assert stop.value.code == 0
    return capsys.readouterr().out


def test_the_help_is_plain_text(capsys):
    texts = [_help([], capsys)] + [
        _help([verb], capsys) for verb in build_parser()._actions[-1].choices
    ]
    for text in texts:
        assert not MARKUP.search(text), text
    assert "exit status" in texts[0] and "--dry-run" in texts[0]


def test_a_negative_number_is_read_as_a_value_and_refused_by_name(capsys):
    error = _fails(["run", "quick", "--p", "-1e-4", "--dry-run"], capsys)
    assert "expected at least one argument" not in error
    assert error.startswith("lonlib: error: perturbations must be in (0, 10], got -0.0001")
    error = _fails(["run", "quick", "--p", "1e-4", "-.5", "--dry-run"], capsys)
    assert "got -0.5" in error


@pytest.mark.parametrize("verb", READERS)
def test_a_missing_folder_or_a_file_is_said_to_be_one(verb, tmp_path, capsys):
    missing = tmp_path / "data" / "nothing"
    error = _fails([verb, str(missing)], capsys)
    assert error == f"lonlib: error: {missing}: no such folder\n"
    a_file = tmp_path / "trials.csv"
    a_file.write_text("p,run\n")
    error = _fails([verb, str(a_file)], capsys)
    assert error.startswith(f"lonlib: error: {a_file}: not a folder")
    assert "--out" not in error and "no experiment" not in error
    assert not missing.exists()


@pytest.mark.parametrize("verb", READERS)
def test_every_verb_refuses_an_empty_folder_in_one_style(verb, tmp_path, capsys):
    error = _fails([verb, str(tmp_path)], capsys)
    assert error.startswith(f"lonlib: error: no experiment in {tmp_path} yet")
    assert list(tmp_path.iterdir()) == []  # nothing created while looking


def test_a_scheduler_chooses_the_dask_executor_over_the_configurations(tmp_path, capsys):
    from lonlib.experiment.executors import session_executor

    assert load_config("quick").executor == "lockstep"
    assert session_executor(None, "lockstep", "dask-local") == "dask"
    assert session_executor(None, "lockstep", None) == "lockstep"
    assert session_executor("pool", "lockstep", None) == "pool"
    out = tmp_path / "quick"
    main(
        [
            "run",
            "quick",
            "--scheduler",
            "dask-local",
            "--workers",
            "2",
            "--out",
            str(out),
            "--dry-run",
        ]
    )
    printed = capsys.readouterr().out
    assert "executor dask, 2 worker(s) on dask-local" in printed
    assert not out.exists()
    # run_experiment itself gets past the executor to its next check (the folder) at once
    config = dataclasses.replace(load_config("quick"), runs=1)
    with pytest.raises(DataWriteError, match="does not exist"):
        run_experiment(config, tmp_path / "no" / "such", scheduler="dask-local", progress=False)
    # an executor named on the command line still has to fit the scheduler
    error = _fails(
        ["run", "quick", "--executor", "lockstep", "--scheduler", "dask-local", "--dry-run"], capsys
    )
    assert "does not use one" in error


def test_a_dry_run_checks_everything_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "exp"
    main(["run", "quick", "--out", str(out), "--dry-run"])
    assert "Nothing computed or written" in capsys.readouterr().out
    assert not out.exists()
    for argv, message in [
        (["run", "quick", "--out", str(tmp_path / "a" / "b")], "does not exist"),
        (["run", "quick", "--executor", "dask"], "needs a scheduler"),
        (["run", "quick", "--slots", "0"], "slots must be"),
        (["run", "quick", "--device", "tpu"], "is not a torch device"),
        (["run", "no-such-config"], "no-such-config"),
        (["analyse", "data/reference", "--docs", str(tmp_path / "none.md")], "no such file"),
        (["calibrate", str(tmp_path / "a" / "b")], "does not exist"),
    ]:
        assert message in _fails([*argv, "--dry-run"], capsys)
    a_file = tmp_path / "file"
    a_file.write_text("")
    assert "a file, not a folder" in _fails(
        ["run", "quick", "--out", str(a_file), "--dry-run"], capsys
    )
    # a folder holding another experiment is refused, as the real run refuses it
    reference = Path(__file__).parents[2] / "data" / "reference"
    assert "different configuration" in _fails(
        ["run", "quick", "--out", str(reference), "--dry-run"], capsys
    )


def _clean(error: str) -> str:
    """``error`` is one line in the one style, with no traceback nor "[Errno N]"."""
    assert error.startswith("lonlib: error: "), error
    assert "Traceback" not in error and "[Errno" not in error, error
    return error


def _copy(tiny_experiment, tmp_path: Path) -> Path:
    """A copy of the tiny experiment's folder, to damage."""
    import shutil

    return Path(shutil.copytree(tiny_experiment[1], tmp_path / "exp"))


def test_file_system_errors_are_said_in_the_one_style(tiny_experiment, tmp_path, capsys):
    experiment = tiny_experiment[1]
    a_file = tmp_path / "afile"
    a_file.write_text("")
    # lon --out a file: the export folder cannot be created
    error = _clean(_fails(["lon", str(experiment), "--out", str(a_file)], capsys))
    assert str(a_file) in error
    # run with a folder as its configuration
    error = _clean(_fails(["run", str(tmp_path), "--dry-run"], capsys))
    assert "is a folder, not a configuration file" in error


@pytest.mark.parametrize("verb", ["analyse", "record"])
def test_an_output_folder_that_is_a_file_is_said_in_the_one_style(
    verb, tiny_experiment, tmp_path, capsys
):
    folder = _copy(tiny_experiment, tmp_path)
    (folder / {"analyse": "figures", "record": "recordings"}[verb]).write_text("")
    error = _clean(_fails([verb, str(folder)], capsys))
    assert str(folder) in error


@pytest.mark.parametrize("text", ["[1, 2]", '{"config": 5}', '"manifest"'])
@pytest.mark.parametrize("verb", READERS)
def test_a_manifest_of_another_shape_is_refused_as_corrupt(verb, text, tmp_path, capsys):
    (tmp_path / "manifest.json").write_text(text)
    for argv in ([verb, str(tmp_path)], [verb, str(tmp_path), "--dry-run"]):
        error = _clean(_fails(argv, capsys))
        assert "manifest.json: not a manifest" in error


def test_a_manifest_of_another_shape_is_refused_by_the_store(tmp_path):
    from lonlib.storage.atomic import CorruptDataError
    from lonlib.storage.layout import read_manifest
    from lonlib.storage.manifest import sessions_with_other_result_path, updated_manifest

    (tmp_path / "manifest.json").write_text("[1, 2]")
    for read in (read_manifest, sessions_with_other_result_path):
        with pytest.raises(CorruptDataError, match="not a manifest"):
            read(tmp_path)
    (tmp_path / "manifest.json").write_text('{"config": 5}')
    with pytest.raises(CorruptDataError, match="not a manifest"):
        updated_manifest(load_config("quick"), tmp_path)


def test_a_calibration_grid_whose_cells_are_not_a_list_is_refused_by_name(tmp_path, capsys):
    grid = tmp_path / "grid.yaml"
    grid.write_text("cells: 5\n")
    error = _clean(_fails(["calibrate", str(tmp_path / "out"), "--grid", str(grid)], capsys))
    assert "cells must be a list" in error


def test_an_output_under_a_file_or_a_folder_as_page_is_said_to_be_one(tmp_path, capsys):
    from lonlib.storage.atomic import check_output_folder

    a_file = tmp_path / "afile"
    a_file.write_text("")
    for out in (a_file / "x", a_file / "x" / "y"):
        error = _clean(_fails(["run", "quick", "--out", str(out), "--dry-run"], capsys))
        assert f"{a_file} is a file, not a folder" in error and "does not exist" not in error
        with pytest.raises(DataWriteError, match="is a file, not a folder"):
            check_output_folder(out)
    error = _clean(_fails(["calibrate", str(a_file / "x"), "--dry-run"], capsys))
    assert "is a file, not a folder" in error
    for argv in (["analyse", "data/reference"], ["calibrate", str(tmp_path / "out")]):
        error = _clean(_fails([*argv, "--docs", str(tmp_path), "--dry-run"], capsys))
        assert f"--docs {tmp_path}: is a folder, not a file" in error


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["lon", "DIR", "--fitness-tolerance", "-1"], "--fitness-tolerance"),
        (["lon", "DIR", "--tolerance", "-1"], "--fitness-tolerance"),
        (["analyse", "DIR", "--fitness-tolerance", "-1"], "--fitness-tolerance"),
        (["analyse", "DIR", "--bins", "0"], "--bins"),
        (["record", "DIR", "--bins", "0"], "--bins"),
        (["record", "DIR", "--limit", "-1"], "--limit"),
        (["verify", "DIR", "--limit", "-1"], "--limit"),
        (["calibrate", "OUT", "--workers", "0"], "--workers"),
        (["run", "quick", "--out", "OUT", "--workers", "0"], "--workers"),
        (["run", "quick", "--out", "OUT", "--drain-after", "-1"], "--drain-after"),
    ],
)
@pytest.mark.parametrize("dry_run", [True, False])
def test_an_option_out_of_range_is_refused_with_or_without_dry_run(
    argv, option, dry_run, tiny_experiment, tmp_path, capsys
):
    argv = [{"DIR": str(tiny_experiment[1]), "OUT": str(tmp_path / "out")}.get(a, a) for a in argv]
    error = _fails([*argv, *["--dry-run"] * dry_run], capsys)
    error = _clean(error.removeprefix(DEPRECATED + "\n"))
    assert error.startswith(f"lonlib: error: {option} must be in"), error
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_record_optima_refuses_a_negative_limit(tiny_experiment, tmp_path):
    from lonlib.analysis.pipeline import record_optima

    with pytest.raises(ValueError, match="limit must be in"):
        record_optima(tiny_experiment[1], limit=-1)


def test_importing_the_command_leaves_torch_unloaded():
    """``lonlib --help`` and ``lonlib status`` start without loading torch."""
    import subprocess
    import sys

    code = "import sys, lonlib.cli; print('torch' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False"


@pytest.mark.parametrize("verb", ["lon", "analyse"])
def test_the_old_tolerance_flag_sets_the_fitness_tolerance_and_says_so(verb, capsys):
    args = build_parser().parse_args([verb, "DIR", "--tolerance", "0.5"])
    assert args.fitness_tolerance == 0.5
    assert capsys.readouterr().err == DEPRECATED + "\n"
    args = build_parser().parse_args([verb, "DIR"])
    assert args.fitness_tolerance == 1e-9
    assert capsys.readouterr().err == ""


def test_the_session_executor_is_part_of_the_experiment_api():
    import lonlib.experiment as experiment

    assert "session_executor" in experiment.__all__
    assert experiment.__all__ == sorted(experiment.__all__, key=lambda n: (n.islower(), n))
    assert experiment.session_executor(None, "serial", None) == "serial"


LINE_YAML = """
name: line
perturbations: [0.001]
runs: 1
tolerance: 1
max_local_searches: 1
task: {gymnasium: lonlib-test/Line-v0, fitness_range: [-200, 0], descriptor: DESCRIPTOR}
ddpg: {batch_size: 16, buffer_size: 200, warmup_steps: 20, max_steps: 60, min_steps: 0,
       patience_steps: 1000}
"""


def _line_yaml(tmp_path: Path, descriptor: str) -> str:
    from tests.task.test_gymnasium_task import Line  # noqa: F401 (registers Line-v0)

    path = tmp_path / "line.yaml"
    path.write_text(LINE_YAML.replace("DESCRIPTOR", descriptor))
    return str(path)


@pytest.mark.parametrize("dry_run", [True, False])
def test_a_descriptor_with_a_wrong_return_is_one_line_before_any_folder(tmp_path, capsys, dry_run):
    out = tmp_path / "out"
    config = _line_yaml(tmp_path, "tests.task.test_gymnasium_behaviour:broken")
    error = _clean(_fails(["run", config, "--out", str(out), *["--dry-run"] * dry_run], capsys))
    assert error == (
        "lonlib: error: task.descriptor (tests.task.test_gymnasium_behaviour:broken): spread "
        "must be a finite number, got nan\n"
    )
    assert not out.exists()


def test_checkpoint_minutes_on_a_gymnasium_task_is_said_not_to_apply(tmp_path, capsys):
    config = _line_yaml(tmp_path, "tests.task.test_gymnasium_behaviour:line_position")
    out = str(tmp_path / "out")
    main(["run", config, "--out", out, "--executor", "lockstep", "--dry-run"])
    assert capsys.readouterr().err == ""
    main(["run", config, "--out", out, "--checkpoint-minutes", "5", "--dry-run"])
    printed = capsys.readouterr()
    assert "Nothing computed or written" in printed.out
    assert printed.err == (
        "lonlib: warning: --checkpoint-minutes does not apply to a Gymnasium task: its lockstep "
        "batch is not checkpointed (an interrupted search re-runs from its start)\n"
    )


@pytest.mark.parametrize(
    "flag, seconds",
    [([], 600.0), (["--checkpoint-minutes", "0"], None), (["--checkpoint-minutes", "5"], 300.0)],
)
def test_run_checkpoints_every_ten_minutes_unless_told(
    tmp_path, monkeypatch, capsys, flag, seconds
):
    """The lockstep runs' in-flight checkpoints: every 10 minutes by default, never with 0."""
    import lonlib.experiment.running as running

    calls = []
    monkeypatch.setattr(running, "run_experiment", lambda *a, **kw: calls.append(kw) or [])
    main(["run", "configs/quick-robust.yaml", "--out", str(tmp_path / "x"), *flag])
    assert [call["checkpoint_seconds"] for call in calls] == [seconds]
