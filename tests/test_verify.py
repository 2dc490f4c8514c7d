"""``lonlib verify``: a real (tiny) experiment replays exactly; damage is found and named."""

import json
import shutil

import pandas as pd
import pytest

from lonlib.cli import main as cli_main
from lonlib.store import optimum_path, trials_path
from lonlib.verify import verify_experiment


def test_a_fresh_experiment_replays_every_stored_number(tiny_experiment, capsys):
    _, out, trials = tiny_experiment
    report = verify_experiment(out)
    assert report.ok and report.findings == []
    assert report.trials == report.replayed == len(trials)
    cli_main(["verify", str(out)])
    assert "verify: OK" in capsys.readouterr().out


@pytest.fixture
def damaged(tiny_experiment, tmp_path):
    _, out, trials = tiny_experiment
    copy = tmp_path / "damaged"
    shutil.copytree(out, copy)
    return copy, trials


def rewrite(folder, p, run, change):
    path = trials_path(folder, p, run)
    table = pd.read_parquet(path)
    change(table)
    table.to_parquet(path)


def test_a_changed_fitness_a_changed_descriptor_and_a_lost_actor_are_errors(damaged, capsys):
    folder, trials = damaged
    first = trials.iloc[0]
    p, run = float(first.p), int(first.run)

    def damage(table):
        table.loc[0, "fitness"] += 0.025
        table.loc[1, "b_turns_0"] += 1.0
        table.loc[1, "label"] = "balancing"

    rewrite(folder, p, run, damage)
    accepted = trials[(trials.p == p) & (trials.run == run) & trials.accepted].iloc[-1]
    optimum_path(folder, p, run, int(accepted["index"])).unlink()
    report = verify_experiment(folder)
    found = {(f.check, f.index) for f in report.errors}
    assert ("fitness", 0) in found and ("consistency", 0) in found
    assert ("descriptor", 1) in found and ("label", 1) in found
    assert ("actor", int(accepted["index"])) in found
    assert not report.ok
    with pytest.raises(SystemExit) as stop:
        cli_main(["verify", str(folder)])
    assert stop.value.code == 1
    assert "[fitness]" in capsys.readouterr().out


def test_data_of_another_result_path_version_gives_warnings_not_errors(damaged):
    folder, trials = damaged
    first = trials.iloc[0]

    def damage(table):
        table["fitness"] += 0.5

    rewrite(folder, float(first.p), int(first.run), damage)
    manifest = folder / "manifest.json"
    data = json.loads(manifest.read_text())
    for session in data["sessions"]:
        session["result_path_version"] = "0-older"
    manifest.write_text(json.dumps(data))
    report = verify_experiment(folder)
    assert report.ok and not report.current_version
    assert {f.check for f in report.warnings} >= {"version", "fitness"}


def test_an_experiment_of_another_result_path_is_not_extended(damaged):
    import dataclasses

    from lonlib.experiment import run_experiment
    from lonlib.store import read_manifest

    folder, _ = damaged
    manifest = folder / "manifest.json"
    data = json.loads(manifest.read_text())
    data["sessions"][0]["result_path_version"] = None
    manifest.write_text(json.dumps(data))
    from lonlib.configs import ExperimentConfig

    config = ExperimentConfig.from_mapping(read_manifest(folder)["config"])
    run_experiment(config, folder, progress=False)  # finished: nothing to sample, no refusal
    with pytest.raises(ValueError, match="result-path version"):
        run_experiment(dataclasses.replace(config, runs=config.runs + 1), folder, progress=False)
    assert json.loads(manifest.read_text()) == data  # the refusal wrote nothing


def test_sessions_of_other_environments_or_kernels_are_warned_about(damaged):
    folder, _ = damaged
    manifest = folder / "manifest.json"
    data = json.loads(manifest.read_text())
    first = data["sessions"][0]
    data["sessions"].append(
        {
            **first,
            "cpu": {**first["cpu"], "torch": "AVX512"},
            "environment": {"installed_sha256": "x"},
        }
    )
    manifest.write_text(json.dumps(data))
    report = verify_experiment(folder, recordings=False)
    assert report.ok
    messages = [f.message for f in report.warnings if f.check == "provenance"]
    assert len(messages) == 2 and any("torch CPU kernels" in m for m in messages)
