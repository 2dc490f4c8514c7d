"""The calibration study: tiny grid end to end, table semantics, resume, validation."""

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest

import lonlib.calibration.study as calibration
from lonlib.calibration.campaign import run_calibration
from lonlib.calibration.drift import integrator_drift
from lonlib.calibration.greedy import greedy_rollout
from lonlib.calibration.report import search_table
from lonlib.calibration.summaries import CELL_COLUMNS
from lonlib.cli import main as cli_main
from lonlib.config import (
    CalibrationConfig,
    Cell,
    PendulumConfig,
    Scoring,
    grid,
    load_calibration,
    named_calibration,
)
from lonlib.config.calibration import RECORD_FORMAT
from lonlib.task.behaviour import LABELS, describe, label
from lonlib.task.policy import actor_spec


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
    # cart, "all rods upright" is that rod's upright share of the executed steps, counted
    # over the nominal steps
    np.testing.assert_allclose(searches["rollout_fitness"], searches["returned_fitness"])
    for column in ("fitness_all", "fitness_mean"):
        np.testing.assert_allclose(searches[column], searches["rollout_fitness"])
    np.testing.assert_allclose(
        searches["upright_share_0"] * searches["end_step"] / config.env.steps,
        searches["rollout_fitness"],
    )
    assert set(searches["behaviour"]) <= set(LABELS)
    assert (searches["end_step"] <= config.env.steps).all()
    assert (searches["cart_range"] >= 0).all()
    assert (searches["robust_min"] <= searches["robust_mean"]).all()
    assert not any(c.startswith("cart_range_") for c in searches.columns)
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
    from lonlib.calibration.summaries import BALANCING_FITNESS, history_summary

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
    # the table of the former hand-stepped loop (numpy's sin/cos), up to rounding noise
    former = {
        "euler": (1.421787481014766, 0.03126572002834238, 14121.313119874818, 156.2237466282012),
        "semi-implicit": (4.0527065e-06, 8.4305115e-08, 1.0226298978839605, 1.0007220578634346),
    }
    columns = ["energy_drift", "momentum_drift", "energy_ratio", "amplitude_ratio"]
    for integrator, values in former.items():
        np.testing.assert_allclose(drift.loc[integrator, columns], values, rtol=1e-7)


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
    monkeypatch.setattr(
        calibration, "run_cell", lambda c, k, *a, **o: computed.append(c) or real(c, k, *a, **o)
    )
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


def test_cells_stored_in_the_former_record_format_are_refused(tiny_study, tmp_path):
    # before the one rollout: per-cart cart ranges, the study's own labels, other arithmetic
    config, out = tiny_study
    cell = config.cells[0]
    record = json.loads((out / "cells" / f"{cell.name}.json").read_text())
    assert record["settings"]["record_format"] == RECORD_FORMAT
    del record["settings"]["record_format"]
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / f"{cell.name}.json").write_text(json.dumps(record))
    with pytest.raises(ValueError, match="other settings"):
        calibration.read_cell(tmp_path, cell, config)


def test_stored_rollouts_describe_the_stored_actors_under_the_studys_scoring(tiny_study):
    config, out = tiny_study
    searches = pd.read_csv(out / "searches.csv")
    for cell in config.cells:
        with np.load(out / "cells" / f"{cell.name}.npz") as data:
            rows = greedy_rollout(data["theta"], cell.env(config.env), config.hp.scoring)
        stored = searches[searches["cell"] == cell.name].reset_index(drop=True)
        pd.testing.assert_frame_equal(stored[list(rows.columns)], rows, check_dtype=False)


def test_a_cell_scores_its_rollouts_with_the_ddpg_scoring(monkeypatch):
    tiny = named_calibration("tiny")
    ddpg = dataclasses.replace(
        tiny.ddpg, warmup_steps=50, robust_starts=3, robust_noise=0.02, robust_seed=9
    )
    config = dataclasses.replace(tiny, cells=tiny.cells[:1], seeds=1, max_steps=100, ddpg=ddpg)
    seen = []
    real = calibration.greedy_rollout
    monkeypatch.setattr(
        calibration, "greedy_rollout", lambda t, e, s: seen.append(s) or real(t, e, s)
    )
    calibration.run_cell(config.cells[0], config)
    assert seen == [Scoring(starts=3, noise=0.02, seed=9)] == [config.hp.scoring]


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
    # the mean of the two carts' ranges: 58 steps of 0.04 m from the start (57 between the
    # positions after the first and the last step, which the descriptor measures today)
    assert 0.04 * 57 - 1e-6 <= push["cart_range"] <= 0.04 * 58 + 1e-6
    assert push["behaviour"] == "stops at boundary"  # ended at a track end, early
    still = rows.iloc[1]  # never moves: the rods hang all episode
    assert (still["end_reason"], still["end_step"]) == ("step_limit", 2000)
    assert still["cart_range"] == 0.0 and abs(still["turns_1"]) < 1e-9
    assert still["upright_share_0"] == 0.0 and still["behaviour"] == "swinging low"
    assert still["robust_mean"] == still["robust_min"] == 0.0


def test_upright_share_is_of_the_executed_steps_the_fitness_of_the_nominal_ones():
    # A rod starting upright without gravity stays upright while a gently pushed cart runs
    # into a near track end: upright all the steps it ran, so its share is 1, while the
    # fitness counts them over the nominal 2000.
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
    assert row["upright_share_0"] == 1.0
    assert row["rollout_fitness"] == row["end_step"] / 2000
    assert rows.iloc[1]["upright_share_0"] == 1.0 == rows.iloc[1]["rollout_fitness"]


def test_greedy_rollout_is_the_behaviour_descriptor_under_the_given_scoring():
    env = PendulumConfig(n_carts=2, steps=150, initial_noise=0.05)
    rng = np.random.default_rng(3)
    thetas = np.stack([actor_spec(2).initial(rng) for _ in range(3)])
    scoring = Scoring(starts=3, noise=0.02, seed=5, eval_seed=7)
    rows = greedy_rollout(thetas, env, scoring)
    assert list(rows.columns) == [
        "rollout_fitness",
        "fitness_all",
        "fitness_mean",
        "end_reason",
        "end_step",
        "upright_share_0",
        "turns_0",
        "upright_share_1",
        "turns_1",
        "cart_range",
        "robust_mean",
        "robust_min",
        "behaviour",
    ]
    for b, row in rows.iterrows():
        d = describe(thetas[b], env, scoring)  # one Actor alone: the same bits
        assert row.to_dict() == {
            "rollout_fitness": d.fitness,
            "fitness_all": d.fitness_all,
            "fitness_mean": d.fitness_mean,
            "end_reason": d.end_reason.lower(),
            "end_step": d.end_step,
            "upright_share_0": d.upright_share[0],
            "turns_0": d.turns[0],
            "upright_share_1": d.upright_share[1],
            "turns_1": d.turns[1],
            "cart_range": d.cart_range,
            "robust_mean": d.robust_mean,
            "robust_min": d.robust_min,
            "behaviour": label(d),
        }
    # an int is the nominal start's eval_seed (the former ``seed`` argument)
    pd.testing.assert_frame_equal(
        greedy_rollout(thetas, env, 7), greedy_rollout(thetas, env, Scoring(eval_seed=7))
    )
    assert not greedy_rollout(thetas, env, 8).equals(greedy_rollout(thetas, env, 7))


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

    from tests.notebooks.test_notebooks import REPO

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
    tiny = named_calibration("tiny")
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
    cli_main(["calibrate", "--grid", "tiny", "--quiet", "--docs", str(readme), str(out)])
    text = readme.read_text()
    assert "not ours" in text and "old" not in text  # only the tiny grid's table changed
    table = (out / "calibration.md").read_text()
    cells, drift = table.split("| integrator | steps |")
    assert cells.strip() in text
    assert "| integrator | steps |" not in text  # the drift table: the default grid's block only
    assert text.endswith("<!-- calibration-tiny:end -->\noutro\n")


def test_a_velocity_cell_with_another_gain_is_its_own_cell_and_physics():
    # the geometry sweep's slower motor (issue 46): gain 0.5 on the velocity motor
    slow = Cell("velocity", "semi-implicit", motor_gain=0.5)
    default = Cell("velocity", "semi-implicit")
    assert default.name == "velocity-tau0.02_semi-implicit_height"  # stored names unchanged
    assert slow.name == "velocity-tau0.02-gain0.5_semi-implicit_height"
    assert slow.env(PendulumConfig()).motor_gain == 0.5
    assert default.env(PendulumConfig(motor_gain=3.0)).motor_gain == 1.0
