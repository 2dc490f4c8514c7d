"""``lonlib verify`` on a Gymnasium task's behaviour descriptor (``task.descriptor``): a
descriptor whose module does not import here still lets every fitness replay (a warning
naming it, the verification incomplete), behaviour stored that nothing replays is reported,
and a replayed ``b_*`` value is compared within the task tolerance relative to its size."""

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest

from lonlib.analysis.verify import TASK_REPLAY_TOLERANCE, verify_experiment
from lonlib.cli import main as cli_main
from lonlib.experiment import run_experiment
from tests.conftest import reseal
from tests.experiment.test_gymnasium_runs import line_config

DESCRIPTOR = "tests.task.test_gymnasium_behaviour:line_position"


@pytest.fixture(scope="module")
def sampled(tmp_path_factory) -> dict[str, Path]:
    """The Line experiment sampled with the descriptor and without it."""
    root = tmp_path_factory.mktemp("verify-task")
    folders = {}
    for name, task in [("described", {"descriptor": DESCRIPTOR}), ("bare", {})]:
        folders[name] = root / name
        run_experiment(line_config(**task), folders[name], progress=False)
    return folders


def copy(sampled, name: str, tmp_path: Path) -> Path:
    return Path(shutil.copytree(sampled[name], tmp_path / name))


def set_descriptor(out: Path, descriptor: str | None) -> None:
    """The stored configuration's descriptor changed (None: removed), the folder resealed."""
    manifest = json.loads((out / "manifest.json").read_text())
    if descriptor is None:
        manifest["config"]["task"].pop("descriptor")
    else:
        manifest["config"]["task"]["descriptor"] = descriptor
    (out / "manifest.json").write_text(json.dumps(manifest))
    reseal(out)


def edit_first_trial(out: Path, **values) -> None:
    """Run 0's first stored trial given ``values`` (columns added if new), resealed."""
    path = next(out.glob("p=*/run_0000/trials.parquet"))
    table = pd.read_parquet(path)
    for column, value in values.items():
        table.loc[0, column] = value
    table.to_parquet(path)
    reseal(out)


@pytest.mark.parametrize(
    ("descriptor", "named"),
    [
        ("lonlib_no_such_module.descriptors:upright", "cannot import 'lonlib_no_such_module"),
        ("tests.task.test_gymnasium_behaviour:absent", "has no function 'absent'"),
    ],
)
def test_a_descriptor_that_does_not_import_still_replays_every_fitness(
    sampled, tmp_path, capsys, descriptor, named
):
    out = copy(sampled, "described", tmp_path)
    set_descriptor(out, descriptor)
    report = verify_experiment(out, recordings=False)
    trials = report.trials
    assert report.replayed == trials and report.starts == trials  # fitness and starts replayed
    assert report.ok and not report.complete
    [warning] = [f for f in report.warnings if f.check == "descriptor"]
    assert warning.message.startswith("task.descriptor: ") and named in warning.message
    assert "not replayed" in warning.message
    # the command reports it all and fails: the stored behaviour went unchecked
    with pytest.raises(SystemExit) as stopped:
        cli_main(["verify", str(out), "--no-recordings"])
    assert stopped.value.code == 1
    printed = capsys.readouterr().out
    assert f"{trials} replayed from their stored Actor" in printed and named in printed
    assert "verify: INCOMPLETE" in printed
    # and a fitness that does not replay is still found
    edit_first_trial(out, fitness=0.123)
    report = verify_experiment(out, recordings=False)
    assert "fitness" in {f.check for f in report.errors}


def test_behaviour_stored_without_a_descriptor_is_reported(sampled, tmp_path):
    out = copy(sampled, "described", tmp_path)
    set_descriptor(out, None)
    report = verify_experiment(out, recordings=False)
    [error] = report.errors
    assert error.check == "descriptor"
    assert error.message == (
        "b_end_distance, b_steps, label stored but not replayed: the configuration names no "
        "task.descriptor"
    )


def test_a_descriptor_over_trials_that_stored_none_is_reported(sampled, tmp_path):
    out = copy(sampled, "bare", tmp_path)
    set_descriptor(out, DESCRIPTOR)
    report = verify_experiment(out, recordings=False)
    assert report.errors and {f.check for f in report.errors} == {"descriptor"}
    assert len(report.errors) == report.trials
    assert all(f.message == "no behaviour descriptor stored" for f in report.errors)


def test_a_stored_column_the_descriptor_does_not_give_is_reported(sampled, tmp_path):
    out = copy(sampled, "described", tmp_path)
    edit_first_trial(out, b_extra=1.0)
    report = verify_experiment(out, recordings=False)
    [error] = report.errors
    assert (error.check, error.run, error.index) == ("descriptor", 0, 0)
    assert error.message == "b_extra stored but not replayed"


def test_sampled_elsewhere_a_behaviour_value_replays_within_a_relative_tolerance(sampled, tmp_path):
    """Replayed elsewhere (another Gymnasium version recorded), ``b_steps`` = 20 stored 20
    x (1 + 1e-10) replays (2e-9 apart: beyond an absolute 1e-9, within a relative one); 20 x
    (1 + 1e-8) is a warning."""
    out = copy(sampled, "described", tmp_path)
    manifest = json.loads((out / "manifest.json").read_text())
    manifest["sessions"][0]["task_environment"]["gymnasium"] = "0.29.1"
    (out / "manifest.json").write_text(json.dumps(manifest))
    assert TASK_REPLAY_TOLERANCE == 1e-9
    edit_first_trial(out, b_steps=20 * (1 + 1e-10))
    report = verify_experiment(out, recordings=False)
    assert report.ok and not [f for f in report.warnings if f.check == "descriptor"]
    edit_first_trial(out, b_steps=20 * (1 + 1e-8))
    report = verify_experiment(out, recordings=False)
    [warning] = [f for f in report.warnings if f.check == "descriptor"]
    assert warning.message.startswith("b_steps stored 20.0000002")


def test_sampled_here_a_behaviour_value_must_replay_bit_for_bit(sampled, tmp_path):
    """Replayed on the sampling's own machine (same CPU dispatch and Gymnasium version),
    ``b_steps`` = 20 stored 20 x (1 + 1e-12), within every tolerance, is an error."""
    out = copy(sampled, "described", tmp_path)
    edit_first_trial(out, b_steps=20 * (1 + 1e-12))
    report = verify_experiment(out, recordings=False)
    assert any("replayed bit for bit" in f.message for f in report.findings)
    [error] = report.errors
    assert (error.check, error.run, error.index) == ("descriptor", 0, 0)
    assert error.message.startswith("b_steps stored 20.00000000002")
