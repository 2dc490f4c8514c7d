"""The calibration study: tiny grid end to end, table semantics, resume, validation."""

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest

import lonlib.calibration as calibration
from lonlib.calibration import (
    BEHAVIOURS,
    CELL_COLUMNS,
    CalibrationConfig,
    Cell,
    behaviour,
    greedy_rollout,
    grid,
    integrator_drift,
    load_calibration,
    named_calibration,
    run_calibration,
)
from lonlib.calibration_report import search_table
from lonlib.cli import main as cli_main
from lonlib.nets import actor_spec
from lonlib.pendulum import PendulumConfig


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory):
    """The tiny grid run through the CLI, its two cells in two processes: (config, folder)."""
    out = tmp_path_factory.mktemp("calibration") / "tiny"
    cli_main(["calibrate", "--grid", "tiny", "--workers", "2", "--quiet", str(out)])
    return named_calibration("tiny"), out


def test_tiny_study_writes_its_tables_and_figure(tiny_study):
    config, out = tiny_study
    cells = pd.read_csv(out / "calibration.csv")
    assert list(cells.columns) == CELL_COLUMNS
    assert list(cells["cell"]) == [cell.name for cell in config.cells]
    assert (out / "calibration.png").stat().st_size > 10_000
    for cell in config.cells:
        assert (out / "cells" / f"{cell.name}.json").exists()
        with np.load(out / "cells" / f"{cell.name}.npz") as data:
            assert data["theta"].shape == (config.seeds, actor_spec(1).n_params)


def test_tiny_study_table_semantics(tiny_study):
    config, out = tiny_study
    cells = pd.read_csv(out / "calibration.csv").set_index("cell")
    searches = pd.read_csv(out / "searches.csv")
    assert len(searches) == config.seeds * len(config.cells)
    # the tiny grid is chosen so that one cell leaves zero and the other does not
    assert sorted(cells["share_left_zero"]) == [0.0, 1.0]
    for name, group in searches.groupby("cell"):
        row = cells.loc[name]
        left = group["best_fitness"] > 0
        assert row["left_zero"] == left.sum() and row["share_left_zero"] == left.mean()
        assert row["best_fitness"] == group["best_fitness"].max()
        assert row["searches"] == config.seeds
        if left.any():
            steps = group["first_nonzero_steps"].dropna()
            assert row["first_nonzero_steps_min"] == steps.min()
            assert row["first_nonzero_steps_max"] == steps.max()
        else:
            assert np.isnan(row["first_nonzero_steps_median"])
    # a search has a first non-zero step exactly when it left zero, within its budget
    assert (searches["first_nonzero_steps"].notna() == (searches["best_fitness"] > 0)).all()
    assert (searches["first_nonzero_steps"].dropna() <= config.max_steps).all()
    assert (searches["env_steps"] == config.max_steps).all()
    # the greedy replay reproduces the score of the Actor the search returned; with one
    # cart, "all rods upright" is that rod's upright share
    np.testing.assert_allclose(searches["rollout_fitness"], searches["returned_fitness"])
    np.testing.assert_allclose(searches["upright_share_0"], searches["rollout_fitness"])
    assert set(searches["behaviour"]) <= set(BEHAVIOURS)
    assert (searches["end_step"] <= config.env.steps).all()
    assert (searches["cart_range_0"] >= 0).all()
    # the gain is blank for the velocity motor, the time constant for the others
    velocity = searches["motor"] == "velocity"
    assert searches.loc[velocity, "motor_gain"].isna().all()
    assert searches.loc[~velocity, "motor_tau"].isna().all()


def test_first_nonzero_step_is_read_from_the_training_history(tiny_study):
    config, out = tiny_study
    for cell in config.cells:
        record = json.loads((out / "cells" / f"{cell.name}.json").read_text())
        for search in record["searches"]:
            steps, fitness = search["history_env_steps"], search["history_greedy_fitness"]
            assert search["best_fitness"] == max(fitness)
            nonzero = [s for s, f in zip(steps, fitness, strict=True) if f > 0]
            assert search["first_nonzero_steps"] == (nonzero[0] if nonzero else None)


def test_history_summary_finds_the_first_nonzero_and_the_first_balancing_policy():
    from lonlib.calibration import BALANCING_FITNESS, history_summary

    steps = [100, 200, 300, 400, 500]
    fitness = [float("nan"), 0.0, 0.3, BALANCING_FITNESS, 0.5]
    assert history_summary(steps, fitness) == {
        "best_fitness": BALANCING_FITNESS,
        "first_nonzero_steps": 300,
        "first_balancing_steps": 400,
    }
    assert history_summary(steps[:3], fitness[:3])["first_balancing_steps"] is None


def test_drift_table_shows_explicit_euler_pumping_energy(tiny_study):
    _, out = tiny_study
    drift = pd.read_csv(out / "drift.csv").set_index("integrator")
    assert drift.loc["euler", "energy_ratio"] > 1.5
    assert drift.loc["semi-implicit", "energy_ratio"] == pytest.approx(1.0, abs=0.05)
    assert drift.loc["euler", "energy_drift"] > 10 * drift.loc["semi-implicit", "energy_drift"]
    assert (drift["momentum_drift"] < 1e-5).all()


def test_integrator_drift_over_an_episode_matches_the_known_amplitude_growth():
    drift = integrator_drift(PendulumConfig(), 2000).set_index("integrator")
    assert drift.loc["euler", "amplitude_ratio"] > 100  # ~x156: explicit Euler pumps
    assert drift.loc["semi-implicit", "amplitude_ratio"] == pytest.approx(1.0, abs=0.01)


def test_a_killed_study_resumes_and_recomputes_only_the_missing_cell(
    tiny_study, tmp_path, monkeypatch
):
    config, out = tiny_study
    copy = tmp_path / "copy"
    (copy / "cells").mkdir(parents=True)
    for path in (out / "cells").iterdir():
        (copy / "cells" / path.name).write_bytes(path.read_bytes())
    lost = config.cells[0]
    (copy / "cells" / f"{lost.name}.json").unlink()  # killed before this cell committed
    computed = []
    real = calibration.run_cell
    monkeypatch.setattr(calibration, "run_cell", lambda c, k: computed.append(c) or real(c, k))
    result = run_calibration(config, copy, progress=False)
    assert computed == [lost]
    pd.testing.assert_frame_equal(
        result.searches.reset_index(drop=True), pd.read_csv(out / "searches.csv"), atol=1e-9
    )
    run_calibration(config, copy, progress=False)
    assert computed == [lost]  # a finished study is read back, not recomputed


def test_a_folder_holding_other_settings_is_refused_before_any_compute(tiny_study, monkeypatch):
    config, out = tiny_study
    monkeypatch.setattr(calibration, "run_cell", lambda *a: pytest.fail("computed"))
    with pytest.raises(ValueError, match="other settings"):
        run_calibration(dataclasses.replace(config, seeds=3), out, progress=False)


def constant_actor(action: float, n_carts: int = 1) -> np.ndarray:
    """An Actor whose output is ``action`` whatever it senses (zero weights, last bias)."""
    theta = np.zeros(actor_spec(n_carts).n_params, dtype=np.float32)
    theta[-n_carts:] = np.log(action / (1 - action))
    return theta


def test_greedy_rollout_reports_end_step_and_cart_range():
    env = PendulumConfig(n_carts=2, motor="velocity", motor_tau=0.02, integrator="semi-implicit")
    rows = greedy_rollout(np.stack([constant_actor(1 - 1e-9, 2), constant_actor(0.5, 2)]), env)
    # both carts at full speed right from the first step: x = x0 + 0.04 k; the right cart
    # (x0 = 0.55 m) passes the 2.95 m track end with its edge at k = 58
    push = rows.iloc[0]
    assert (push["end_reason"], push["end_step"]) == ("boundary", 58)
    assert push["cart_range_0"] == pytest.approx(0.04 * 58)
    assert push["cart_range_1"] == pytest.approx(0.04 * 58)
    assert push["behaviour"] == "ends early"
    still = rows.iloc[1]  # never moves: the rods hang all episode
    assert (still["end_reason"], still["end_step"]) == ("step_limit", 2000)
    assert still["cart_range_0"] == 0.0 and abs(still["turns_1"]) < 1e-9
    assert still["upright_share_0"] == 0.0 and still["behaviour"] == "hangs"


def test_upright_share_counts_only_the_steps_an_episode_ran():
    # A rod starting upright without gravity stays upright while a gently pushed cart runs
    # into a near track end; its share is the steps it ran over the nominal 2000.
    env = PendulumConfig(
        n_carts=1,
        motor="acceleration",
        motor_gain=0.01,
        gravity=1e-9,
        initial_angle=0.0,
        track_half_length_base=0.5,
    )
    # batched with an Actor that never pushes, so the rollout goes on after the first ends
    rows = greedy_rollout(np.stack([constant_actor(1 - 1e-9), constant_actor(0.5)]), env)
    row = rows.iloc[0]
    assert row["end_reason"] == "boundary" and 100 < row["end_step"] < 2000
    assert row["upright_share_0"] == row["end_step"] / 2000 == row["rollout_fitness"]
    assert rows.iloc[1]["upright_share_0"] == 1.0


def test_net_turns_are_signed_and_survive_wrapping():
    steps = np.arange(0, 20, 1.0)  # one radian per step, 19 rad in all
    angles = np.stack([np.mod(steps, 2 * np.pi), np.mod(-steps, 2 * np.pi)], axis=1)
    np.testing.assert_allclose(calibration.net_turns(angles), [19 / (2 * np.pi), -19 / (2 * np.pi)])


@pytest.mark.parametrize(
    ("end", "shares", "turns", "label"),
    [
        ("collision", (0.9, 0.9), (0.1, 0.1), "ends early"),
        ("step_limit", (0.9, 0.6), (0.5, -0.9), "balances"),
        ("step_limit", (0.9, 0.4), (0.5, -0.9), "swings"),
        ("step_limit", (0.9, 0.6), (0.5, -1.5), "swings"),
        ("step_limit", (0.5, 0.5), (0.5, -2.0), "spins"),
        ("step_limit", (0.0, 0.0), (0.3, -0.5), "hangs"),
    ],
)
def test_behaviour_labels(end, shares, turns, label):
    row = {"end_reason": end}
    for i in range(2):
        row[f"upright_share_{i}"], row[f"turns_{i}"] = shares[i], turns[i]
    assert behaviour(row, 2) == label


def test_default_grid_covers_every_motor_and_integrator():
    config = named_calibration("default")
    assert {(c.motor, c.integrator) for c in config.cells} == {
        (m, i) for m in ("force", "acceleration", "velocity") for i in ("euler", "semi-implicit")
    }
    assert config.hp.min_steps == config.hp.max_steps == 150_000
    assert config.hp.batch_size == 256 and config.hp.threads == 1
    assert len(grid(force_gains=(1.0, 5.0), velocity_taus=(0.02, 0.1))) == 10


def test_yaml_grid_and_validation(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text(
        "base: tiny\nseeds: 1\nddpg: {learning_rate: 0.0005}\n"
        "cells:\n  - {motor: acceleration, integrator: euler, motor_gain: 2.0}\n"
    )
    config = load_calibration(path)
    assert config.name == "mine" and config.seeds == 1 and config.ddpg.learning_rate == 0.0005
    assert config.cells == (Cell("acceleration", "euler", motor_gain=2.0),)
    path.write_text("base: tiny\nseedz: 2\n")
    with pytest.raises(ValueError, match="seedz"):
        load_calibration(path)
    with pytest.raises(ValueError, match="motor"):
        Cell(motor="torque")
    with pytest.raises(ValueError, match="motor_tau"):  # shorter than dt: refused up front
        CalibrationConfig(cells=(Cell("velocity", motor_tau=0.01),))
    with pytest.raises(ValueError, match="repeat"):
        CalibrationConfig(cells=(Cell(), Cell()))
    with pytest.raises(ValueError, match="seeds"):
        CalibrationConfig(seeds=0)
    with pytest.raises(ValueError, match="tiny"):
        load_calibration("huge")


def test_notebook_runs_the_tiny_grid(tmp_path):
    import papermill as pm

    from tests.test_notebooks import REPO

    out = tmp_path / "study"
    pm.execute_notebook(
        str(REPO / "notebooks" / "calibrate_physics.ipynb"),
        str(tmp_path / "calibrate_physics.ipynb"),
        parameters={"grid": "tiny", "max_steps": 120, "workers": 1, "out": str(out)},
        progress_bar=False,
        cwd=str(REPO),
    )
    cells = pd.read_csv(out / "calibration.csv")
    assert len(cells) == 2 and (cells["searches"] == 2).all()
    assert (out / "calibration.png").stat().st_size > 0


def test_episodes_before_the_first_update_do_not_hide_the_best_fitness():
    nan = float("nan")
    summary = calibration.history_summary([40, 80, 120, 160], [nan, 0.0, 0.25, 0.1])
    assert summary == {
        "best_fitness": 0.25,
        "first_nonzero_steps": 120,
        "first_balancing_steps": None,
    }
    assert calibration.history_summary([40], [nan]) == {
        "best_fitness": 0.0,
        "first_nonzero_steps": None,
        "first_balancing_steps": None,
    }


def test_a_warm_up_longer_than_an_episode_still_gives_a_best_fitness(tmp_path):
    tiny = calibration.named_calibration("tiny")
    config = dataclasses.replace(
        tiny, cells=tiny.cells[:1], ddpg=dataclasses.replace(tiny.ddpg, warmup_steps=120)
    )
    record, _ = calibration.run_cell(config.cells[0], config)
    assert any(np.isnan(s["history_greedy_fitness"][0]) for s in record["searches"])
    table = search_table([record])
    assert table["best_fitness"].notna().all()
    assert (table["best_fitness"] > 0).any()


def test_readme_gets_the_grids_table_between_its_own_markers(tiny_study, tmp_path):
    _, out = tiny_study
    readme = tmp_path / "README.md"
    readme.write_text("intro\n<!-- calibration:begin -->\nnot ours\n<!-- calibration:end -->\n")
    with pytest.raises(SystemExit):  # the tiny grid's markers are missing: refused at once
        cli_main(["calibrate", "--grid", "tiny", "--quiet", "--readme", str(readme), str(out)])
    readme.write_text(
        readme.read_text()
        + "<!-- calibration-tiny:begin -->\nold\n<!-- calibration-tiny:end -->\noutro\n"
    )
    cli_main(["calibrate", "--grid", "tiny", "--quiet", "--readme", str(readme), str(out)])
    text = readme.read_text()
    assert "not ours" in text and "old" not in text  # only the tiny grid's table changed
    assert (out / "calibration.md").read_text().strip() in text
    assert text.endswith("<!-- calibration-tiny:end -->\noutro\n")
