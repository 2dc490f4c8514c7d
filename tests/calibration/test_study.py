"""The learner-side study (issue 31): the height-product reward, exploring starts, continue
from best, the judged-policy summary, validation, and kill-and-resume of a cell in flight."""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

import lonlib.calibration.inflight as inflight
import lonlib.calibration.study as study
from lonlib.calibration import run_calibration
from lonlib.calibration.cell_store import json_roundtrip
from lonlib.calibration.drift import integrator_drift
from lonlib.calibration.report import readme_markers, write_outputs
from lonlib.calibration.summaries import judged_summary
from lonlib.cli import main
from lonlib.config import (
    CalibrationConfig,
    Cell,
    ExperimentConfig,
    PendulumConfig,
    Scoring,
    StartSpread,
    load_calibration,
    named_calibration,
    named_config,
    with_overrides,
)
from lonlib.ddpg.checkpoint import checkpoint_configs, from_checkpoint, to_checkpoint
from lonlib.ddpg.slots import LocalSearchResult
from lonlib.ddpg.trainer import SlotTrainer, greedy_scores
from lonlib.task.behaviour import describe_actors, describe_rollout, label
from lonlib.task.pendulum import CoupledPendulums
from lonlib.task.policy import actor_spec, critic_spec
from lonlib.task.rollout import nominal_offsets, run_actors

ROOT = Path(__file__).resolve().parents[2]
TINY = named_calibration("tiny")
BASE = TINY.cells[0]
BASE_TWO_CART = Cell()  # the two-cart study's default cell


def tiny_study(*cells: Cell) -> CalibrationConfig:
    """The tiny grid (one cart, 400 env steps per search) with ``cells``."""
    return dataclasses.replace(TINY, name="tiny-study", cells=cells)


# ------------------------------------------------------------------------ the reward
@pytest.mark.parametrize("reward", ["height", "height-product"])
def test_height_product_reward_is_the_product_of_the_rods_heights(reward):
    cfg = PendulumConfig(n_carts=3, reward=reward, gravity=1e-9, hinge_friction=0.0)
    sim = CoupledPendulums(cfg, 2)
    angles = np.array([[0.0, math.pi / 2, 2.0], [0.3, 0.0, 0.0]])
    sim.phi[:] = angles
    out = sim.step(np.full((2, 3), 0.5))  # no force, (almost) no gravity: the rods stay put
    heights = 0.5 * (1.0 + np.cos(angles))
    expected = heights.prod(axis=1) if reward == "height-product" else heights.mean(axis=1)
    np.testing.assert_allclose(out.reward, expected, atol=1e-9)


def test_one_rod_up_earns_half_of_what_both_up_do_under_the_product():
    cfg = PendulumConfig(n_carts=2, reward="height-product", gravity=1e-9)
    sim = CoupledPendulums(cfg, 3)
    sim.phi[:] = np.array([[0.0, 0.0], [0.0, math.pi / 2], [0.0, math.pi]])
    reward = sim.step(np.full((3, 2), 0.5)).reward
    np.testing.assert_allclose(reward, [1.0, 0.5, 0.0], atol=1e-9)


def test_unknown_reward_is_refused_naming_the_field_and_choices():
    with pytest.raises(ValueError, match="reward.*height-product"):
        Cell(reward="product")
    with pytest.raises(ValueError, match="reward"):
        PendulumConfig(reward="product")


# ------------------------------------------------------------------ exploring starts
def test_start_spread_refuses_negative_or_too_wide_half_widths_by_name():
    with pytest.raises(ValueError, match=r"starts\.angle"):
        StartSpread(angle=-0.1)
    with pytest.raises(ValueError, match=r"starts\.angular_velocity"):
        StartSpread(angular_velocity=-1.0)
    with pytest.raises(ValueError, match=r"starts\.position"):
        StartSpread(position=1.0)
    with pytest.raises(ValueError, match=r"unknown starts key"):
        CalibrationConfig.from_mapping({"base": "tiny", "starts": {"spread": 1.0}})
    with pytest.raises(ValueError, match=r"starts\.angle"):
        CalibrationConfig.from_mapping({"base": "tiny", "starts": {"angle": -1.0}})


def trainer(spread, seeds=(1, 2, 3), judge_every=0, **ddpg):
    env = PendulumConfig(n_carts=2, steps=60, upright_angle=3.05)  # both aggregations > 0
    rng = np.random.default_rng(0)
    k = len(seeds)
    thetas = np.stack([actor_spec(2).initial(rng) for _ in range(k)])
    omegas = np.stack([critic_spec(2).initial(rng) for _ in range(k)])
    hp = dataclasses.replace(TINY.hp, batch_size=32, judge_every=judge_every, **ddpg)
    return SlotTrainer(thetas, omegas, list(seeds), env, hp, start_spread=spread), thetas, env, hp


def test_exploring_starts_spread_the_training_starts_but_not_the_greedy_evaluation():
    fixed, thetas, env, hp = trainer(None)
    spread = StartSpread(angle=1.0, angular_velocity=2.0).half_widths
    exploring, *_ = trainer(spread)
    assert (fixed.sim.phi == math.pi).all() and (fixed.sim.phi_dot == 0).all()
    offset = np.angle(np.exp(1j * (exploring.sim.phi - math.pi)))
    assert 0 < np.abs(offset).max() <= 1.0 and len(np.unique(offset)) == offset.size
    assert 0 < np.abs(exploring.sim.phi_dot).max() <= 2.0
    assert (exploring.sim.x == fixed.sim.x).all() and (exploring.sim.x_dot == 0).all()
    # the start's greedy fitness is Algorithm 1 from the fixed start in both
    starts = [s.result.start_fitness for s in exploring.searches]
    assert starts == [s.result.start_fitness for s in fixed.searches]
    assert starts == list(greedy_scores(thetas, env, hp.scoring)[0])


def test_an_exploring_cell_scores_its_optima_from_the_fixed_start():
    config = tiny_study(BASE, dataclasses.replace(BASE, exploring_starts=True))
    _, (fixed, _) = study.run_cell(config.cells[0], config)
    explore, (thetas, _) = study.run_cell(config.cells[1], config)
    for a, b in zip(fixed, thetas, strict=True):  # other training episodes, other Actors
        assert not np.array_equal(a, b)
    fitness, _ = greedy_scores(thetas, config.cells[1].env(config.env), config.hp.scoring)
    for search, f in zip(explore["searches"], fitness, strict=True):
        assert search["returned_fitness"] == f == search["rollout_fitness"]
        # every judged policy was scored from the fixed start too (all = the fitness)
        judged = [x for x in search["history_greedy_fitness"] if not math.isnan(x)]
        assert judged == search["history_fitness_all"]


# ----------------------------------------------------------------------- upright start
def test_an_upright_start_cell_trains_and_scores_from_upright_and_keeps_old_cells_names():
    upright = dataclasses.replace(BASE, initial_angle=0.0)
    assert upright.name == BASE.name + "_upright-start"
    assert dataclasses.replace(BASE, initial_angle=1.0).name == BASE.name + "_start1"
    # a hanging cell is stored as before the setting existed; an upright one names it
    assert "initial_angle" not in BASE.to_dict() and upright.to_dict()["initial_angle"] == 0.0
    config = tiny_study(BASE, upright)
    record, (thetas, _) = study.run_cell(upright, config)
    env = upright.env(config.env)
    assert env.initial_angle == 0.0 and record["cell"]["initial_angle"] == 0.0
    fitness, _ = greedy_scores(thetas, env, config.hp.scoring)
    hanging, _ = greedy_scores(thetas, BASE.env(config.env), config.hp.scoring)
    for search, f, h in zip(record["searches"], fitness, hanging, strict=True):
        assert search["returned_fitness"] == f == search["rollout_fitness"] != h
    rng = np.random.default_rng(0)
    actors, critics = actor_spec(1).initial(rng)[None], critic_spec(1).initial(rng)[None]
    started = SlotTrainer(actors, critics, [1], env, config.hp)
    assert (started.sim.phi == 0.0).all()  # every training episode starts upright


@pytest.mark.parametrize("angle", [-0.1, 2 * math.pi, float("nan")])
def test_a_start_angle_out_of_range_is_refused_by_name(angle):
    with pytest.raises(ValueError, match="initial_angle must be"):
        dataclasses.replace(BASE, initial_angle=angle)


@pytest.mark.parametrize("index", [0, 1])
@pytest.mark.parametrize(
    ("cell", "message"),
    [
        ({"initial_angle": 7.0}, r"\.initial_angle must be in \[0, 2 pi\)"),
        ({"motor": "jet"}, r"\.motor must be one of"),
        ({"motor_tau": "fast"}, r"\.motor_tau must be a number"),
        ({"bogus": 1}, r" must be a mapping of"),
        ({"motor_tau": 0.01}, r": motor_tau must be in \[dt / substeps"),  # the cell's physics
    ],
)
def test_a_grid_cells_bad_field_is_refused_naming_the_cell_and_field(index, cell, message):
    cells = [{"reward": "slow-height"}, {"reward": "slow-height"}]
    cells[index] = {"reward": "height", **cell}
    with pytest.raises(ValueError, match=rf"^cells\[{index}\]{message}"):
        CalibrationConfig.from_mapping({"base": "tiny", "cells": cells})


def test_a_repeated_cell_is_refused_naming_both():
    cells = [{"reward": "height"}, {"reward": "slow-height"}, {"reward": "height"}]
    with pytest.raises(ValueError, match=r"^cells\[2\] repeats cells\[0\] \(velocity"):
        CalibrationConfig.from_mapping({"base": "tiny", "cells": cells})


def test_the_committed_study_cells_read_back_with_the_grid_and_keep_their_identity():
    config = load_calibration(ROOT / "configs" / "study-two-cart.yaml")
    out = ROOT / "data" / "studies" / "two-cart"
    stored = {path.stem for path in (out / "cells").glob("*.json")}
    assert len(stored) >= 4
    for cell in config.cells:
        if cell.name in stored:
            record = study.read_cell(out, cell, config)  # refused if its settings changed
            assert record is not None and record["cell"] == json_roundtrip(cell.to_dict())


def test_a_base_start_angle_is_refused_naming_the_cells_own():
    with pytest.raises(ValueError, match=r"env\.initial_angle must be pi.*cells\[i\]"):
        CalibrationConfig.from_mapping({"base": "tiny", "env": {"initial_angle": 0.0}})


def test_the_reports_mark_an_upright_cell_among_cells_stored_before_the_setting():
    from lonlib.calibration.report import (
        calibration_markdown,
        cell_table,
        search_table,
        study_markdown,
        study_table,
    )

    out = ROOT / "data" / "studies" / "two-cart" / "cells"
    old = json.loads((out / f"{BASE_TWO_CART.name}.json").read_text())
    assert "initial_angle" not in old["cell"]  # stored before the setting existed
    upright = json.loads(json.dumps(old))
    upright["cell"]["initial_angle"] = 0.0
    upright["name"] = BASE_TWO_CART.name + "_upright-start"
    records = [old, upright]
    searches = search_table(records)
    table = study_table(searches)
    assert list(table["initial_angle"]) == [math.pi, 0.0]
    rows = study_markdown(table).splitlines()[2:]
    assert "| initial |" in rows[0] and "| initial, upright |" in rows[1]
    cells = calibration_markdown(
        cell_table(searches, records), integrator_drift(TINY.env, steps=20)
    )
    assert "height (upright-start)" in cells and "| height |" in cells


# ------------------------------------------------------------------- continue from best
def test_continue_from_a_cell_missing_from_the_grid_is_refused_before_compute():
    with pytest.raises(ValueError, match=r"cells\[0\]\.continue_from.*earlier cell"):
        tiny_study(dataclasses.replace(BASE, continue_from=BASE.name))
    with pytest.raises(ValueError, match=r"cells\[1\]\.continue_from"):
        tiny_study(BASE, dataclasses.replace(BASE, continue_from="velocity-nope"))


def test_a_continue_cell_starts_from_the_stored_best_actors_and_critics(tmp_path, monkeypatch):
    config = tiny_study(BASE, dataclasses.replace(BASE, continue_from=BASE.name))
    starts = []
    real = SlotTrainer.__init__

    def spy(self, thetas, omegas, seeds, *args, **kwargs):
        starts.append((np.array(thetas), np.array(omegas), list(seeds)))
        real(self, thetas, omegas, seeds, *args, **kwargs)

    monkeypatch.setattr(SlotTrainer, "__init__", spy)
    run_calibration(config, tmp_path, progress=False)
    with np.load(tmp_path / "cells" / f"{BASE.name}.npz") as source:
        np.testing.assert_array_equal(starts[1][0], source["theta"])
        np.testing.assert_array_equal(starts[1][1], source["omega"])
    assert not np.array_equal(starts[0][0], starts[1][0])
    assert starts[1][2] != starts[0][2]  # fresh random streams
    record = json.loads((tmp_path / "cells" / f"{config.cells[1].name}.json").read_text())
    source_text = (tmp_path / "cells" / f"{BASE.name}.json").read_text()
    assert "\n" not in source_text  # a compact record: its histories run to ~15k episodes
    source_record = json.loads(source_text)
    assert [s["start_fitness"] for s in record["searches"]] == [
        s["returned_fitness"] for s in source_record["searches"]
    ]


def test_a_continue_cell_whose_source_holds_no_critics_is_refused_before_compute(
    tmp_path, monkeypatch
):
    config = tiny_study(BASE, dataclasses.replace(BASE, continue_from=BASE.name))
    run_calibration(dataclasses.replace(config, cells=(BASE,)), tmp_path, progress=False)
    npz = tmp_path / "cells" / f"{BASE.name}.npz"
    with np.load(npz) as data:
        theta = data["theta"]
    np.savez_compressed(npz, theta=theta)  # as stored before the study kept Critics
    monkeypatch.setattr(study, "run_cell", lambda *a, **k: pytest.fail("computed"))
    with pytest.raises(ValueError, match="continue_from.*no Critics"):
        run_calibration(config, tmp_path, progress=False)


# ------------------------------------------------------------------ judged summary
def test_judged_summary_finds_the_first_optima_under_both_aggregations():
    steps = [100, 200, 300, 400, 500, 600]
    fitness_all = [0.0, 0.3, 0.2, 0.35, 0.95, 0.5]
    fitness_mean = [0.2, 0.6, 0.7, 0.65, 0.96, 0.5]
    labels = [
        "swinging low",
        "spinning",
        "one rod up",  # not an optimum under all (0.2 < 0.3), one under mean (0.7 > 0.6)
        "one rod up",  # an optimum under all only
        "balancing",
        "balancing",  # never an optimum
    ]
    out = judged_summary(steps, fitness_all, fitness_mean, labels)
    assert out == {
        "best_all": 0.95,
        "first_090_all_steps": 500,
        "first_balancing_all_steps": 500,
        "first_rod_up_all_steps": 400,
        "best_mean": 0.96,
        "first_090_mean_steps": 500,
        "first_balancing_mean_steps": 500,
        "first_rod_up_mean_steps": 300,
    }
    never = judged_summary(steps[:2], fitness_all[:2], fitness_mean[:2], labels[:2])
    assert never["first_090_all_steps"] is None and never["first_rod_up_mean_steps"] is None
    assert judged_summary([], [], [], [])["best_all"] == 0.0


def test_judged_labels_are_the_behaviour_labels_of_the_judged_policies():
    config = tiny_study(BASE)
    record, _ = study.run_cell(BASE, config)
    for search in record["searches"]:
        assert record["labels"][search["history_label"][-1]] in record["labels"]
        assert search["best_all"] == max(search["history_fitness_all"])
        # the returned Actor is one of the judged policies: its label is among theirs
        assert search["behaviour"] in [record["labels"][i] for i in search["history_label"]]
        assert search["returned_fitness"] == search["best_all"]


# ------------------------------------------------------------------ judging
def finish(*trainers: SlotTrainer) -> list[list[LocalSearchResult]]:
    """Step the trainers together until every search ended; each one's results by tag."""
    done: list[dict] = [{} for _ in trainers]
    while any(t.busy.any() for t in trainers):
        for t, out in zip(trainers, done, strict=True):
            out.update(t.step() if t.busy.any() else [])
    return [[out[tag] for tag in sorted(out)] for out in done]


def timeless(history):
    return [dataclasses.replace(h, seconds=0.0) for h in history]


@pytest.mark.parametrize("estimate", ["nominal", "robust"])
def test_a_judged_policy_is_described_from_the_rollout_that_scored_it(estimate):
    slots, _, env, hp = trainer(None, fitness_estimate=estimate, robust_starts=2)
    batches = []
    log = study.JudgedLog(env, 3)
    slots.on_judged = lambda judged, nominal: (batches.append(judged), log(judged, nominal))
    (results,) = finish(slots)
    assert len(results) == 3
    judged = [entry for batch in batches for entry in batch]
    assert len(judged) > 20
    alone = describe_actors(np.stack([j[2] for j in judged]), env, Scoring(starts=1))
    for tag in range(3):
        mine = [d for (t, _, _), d in zip(judged, alone, strict=True) if t == tag]
        rows = log.rows[tag]
        assert rows["env_steps"] == [r.env_steps for t, r, _ in judged if t == tag]
        assert rows["fitness_all"] == [d.fitness_all for d in mine]
        assert rows["fitness_mean"] == [d.fitness_mean for d in mine]
        assert rows["label"] == [study.LABELS.index(label(d)) for d in mine]
    assert any(d.fitness_all != d.fitness_mean for d in alone)  # two carts: they differ
    assert len({label(d) for d in alone}) > 1
    for (_, record, _), d in zip(judged, alone, strict=True):
        if estimate == "nominal":
            assert record.greedy_fitness == d.fitness


def test_a_described_rollout_is_describe_actors_without_the_robust_fields():
    slots, thetas, env, _ = trainer(None)
    nominal = run_actors(thetas, env, np.repeat(nominal_offsets(env), 3, axis=1), trace=True)
    for row, alone in enumerate(describe_actors(thetas, env, Scoring(starts=1))):
        ours = describe_rollout(nominal, env, row)
        robust = {f.name: 0.0 for f in dataclasses.fields(ours) if f.name.startswith("robust")}
        assert math.isnan(ours.robust_mean)
        assert dataclasses.replace(ours, **robust) == dataclasses.replace(alone, **robust)


@pytest.mark.parametrize("estimate", ["nominal", "robust"])
def test_tracing_the_judge_changes_no_score(estimate):
    options = {"fitness_estimate": estimate, "robust_starts": 2}
    scored, traced = trainer(None, **options)[0], trainer(None, **options)[0]
    traced.on_judged = lambda judged, nominal: None
    ours, theirs = finish(scored, traced)
    assert len(ours) == 3
    for a, b in zip(ours, theirs, strict=True):
        assert timeless(a.history) == timeless(b.history) and a.fitness == b.fitness
        np.testing.assert_array_equal(a.theta, b.theta)


@pytest.mark.parametrize(("every", "count_start"), [(1, False), (100, False), (100, True)])
def test_judge_every_judges_only_the_episodes_that_cross_its_multiples(every, count_start):
    # a warm-up longer than two episodes (60 steps each): count_start judges warm-up ends too
    options = {"count_start": count_start, "warmup_steps": 130 if count_start else 50}
    dense, sparse = finish(
        trainer(None, **options)[0], trainer(None, judge_every=every, **options)[0]
    )
    assert len(sparse) == 3
    warmup = options["warmup_steps"]
    for everyone, search in zip(dense, sparse, strict=True):
        ends = np.array([h.env_steps for h in search.history])
        before = np.concatenate([[0], ends[:-1]])
        crossing = ends // every > before // every
        expected = ((ends >= warmup) | count_start) & crossing
        judged = ~np.isnan([h.greedy_fitness for h in search.history])
        np.testing.assert_array_equal(judged, expected)
        assert 0 < judged.sum() < len(ends) or every == 1
        # judging less changes which policies are judged, not the training
        for a, b, was_judged in zip(everyone.history, search.history, judged, strict=True):
            assert a.episode_return == b.episode_return and a.env_steps == b.env_steps
            assert not was_judged or a.greedy_fitness == b.greedy_fitness
        best = max(h.greedy_fitness for h, j in zip(search.history, judged, strict=True) if j)
        assert search.fitness == max(best, search.start_fitness if count_start else best)


def test_judge_every_must_leave_room_for_the_patience():
    hp = dataclasses.replace(TINY.hp, min_steps=0, patience_steps=250, judge_every=300)
    with pytest.raises(ValueError, match="judge_every must be < ddpg.patience_steps"):
        ExperimentConfig(ddpg=hp)
    with pytest.raises(ValueError, match="judge_every must be < ddpg.patience_steps"):
        trainer(None, min_steps=0, patience_steps=250, judge_every=300)
    ExperimentConfig(ddpg=dataclasses.replace(hp, min_steps=hp.max_steps))  # no patience
    ExperimentConfig(ddpg=dataclasses.replace(hp, judge_every=249))


def test_a_study_budget_is_not_checked_against_the_ddpg_sections_own_budget():
    config = CalibrationConfig.from_mapping(
        {"base": "tiny", "max_steps": 1_000_000, "ddpg": {"judge_every": 200_000}}
    )
    assert config.hp.judge_every == 200_000
    assert with_overrides(load_calibration("configs/study-two-cart.yaml"), None, 1000, None)


def test_a_trainer_checkpoint_names_judge_every_only_when_set_and_reads_without_it():
    zero, every = trainer(None)[0], trainer(None, judge_every=100)[0]
    plain_zero, _ = to_checkpoint(zero)
    plain_every, tensors = to_checkpoint(every)
    assert "judge_every" not in plain_zero["ddpg"]  # the layout of checkpoints before it
    assert plain_every["ddpg"]["judge_every"] == 100
    assert checkpoint_configs(plain_zero)[1].judge_every == 0
    restored = from_checkpoint(plain_every, tensors)
    assert restored.hp.judge_every == 100


def judging(config: CalibrationConfig, every: int) -> CalibrationConfig:
    return dataclasses.replace(config, ddpg=dataclasses.replace(config.ddpg, judge_every=every))


def test_judge_every_is_refused_out_of_range_by_name():
    with pytest.raises(ValueError, match="judge_every"):
        trainer(None, judge_every=-1)
    with pytest.raises(ValueError, match="judge_every"):
        judging(TINY, -1)
    with pytest.raises(ValueError, match="judge_every"):
        CalibrationConfig.from_mapping({"base": "tiny", "ddpg": {"judge_every": 1.5}})


def test_judge_every_is_a_stored_setting_only_when_set():
    assert "judge_every" not in TINY.settings()["ddpg"]  # stored cells judged every episode
    assert judging(TINY, 100).settings()["ddpg"]["judge_every"] == 100
    reference = json.loads((ROOT / "data/reference/manifest.json").read_text())["config"]
    assert "judge_every" not in reference["ddpg"]  # stored before the field existed
    stored = ExperimentConfig.from_mapping(reference)
    assert stored.comparable() == named_config("reference").comparable()
    assert "judge_every" not in stored.comparable()["ddpg"]
    sparse = dataclasses.replace(stored, ddpg=dataclasses.replace(stored.ddpg, judge_every=500))
    assert sparse.comparable()["ddpg"]["judge_every"] == 500


def test_a_cell_judged_every_100_env_steps_logs_only_those_policies():
    config = judging(tiny_study(BASE), 100)
    record, _ = study.run_cell(BASE, config)
    dense, _ = study.run_cell(BASE, tiny_study(BASE))
    for search, every_episode in zip(record["searches"], dense["searches"], strict=True):
        ends = search["history_env_steps"]
        judged = search["history_judged_env_steps"]
        assert judged and set(judged) < set(every_episode["history_judged_env_steps"])
        crossing = [e for e, b in zip(ends, [0, *ends[:-1]], strict=True) if e // 100 > b // 100]
        assert judged == [e for e in crossing if e >= config.hp.warmup_steps]


# ------------------------------------------------------------------ a study in progress
def test_the_stored_cells_of_an_unfinished_study_are_reported_without_training(
    tmp_path, monkeypatch
):
    explore = dataclasses.replace(BASE, exploring_starts=True)
    config = tiny_study(BASE, explore)
    run_calibration(tiny_study(BASE), tmp_path, progress=False)  # the first cell only
    with pytest.raises(ValueError, match="not finished yet.*explore"):
        write_outputs(config, tmp_path)
    monkeypatch.setattr(study, "run_cell", lambda *a, **k: pytest.fail("trained"))
    page = tmp_path / "page.md"
    begin, end = readme_markers(config.name)
    page.write_text(f"# study\n{begin}\n{end}\n")
    grid = tmp_path / "grid.yaml"
    grid.write_text(yaml.safe_dump(json_roundtrip(config.to_dict())))
    main(["calibrate", str(tmp_path), "--grid", str(grid), "--stored-only", "--docs", str(page)])
    table = pd.read_csv(tmp_path / "study.csv")
    assert list(table["cell"]) == [BASE.name]
    markdown = (tmp_path / "calibration.md").read_text()
    assert f"Cells not finished yet: `{explore.name}`" in markdown
    assert f"Cells not finished yet: `{explore.name}`" in page.read_text()
    with pytest.raises(ValueError, match="not finished yet"):
        write_outputs(tiny_study(explore), tmp_path, stored_only=True)  # none stored


# ------------------------------------------------------------------ kill and resume
@pytest.mark.parametrize("judge_every", [0, 100])
def test_a_study_killed_mid_cell_resumes_to_the_same_cells(tmp_path, monkeypatch, judge_every):
    config = tiny_study(
        BASE,
        dataclasses.replace(BASE, exploring_starts=True),
        dataclasses.replace(BASE, continue_from=BASE.name),
    )
    config = judging(config, judge_every)
    options = {"progress": False, "checkpoint_seconds": 0, "check_steps": 50}
    whole = run_calibration(config, tmp_path / "whole", **options)

    writes = []
    write = inflight.atomic_write

    def die_committing_the_9th(path, data):  # the second cell: 7 checkpoints per cell
        writes.append(path)
        if len(writes) == 2 * 9:  # its data file is written, its metadata is not
            raise KeyboardInterrupt
        write(path, data)

    killed = tmp_path / "killed"
    monkeypatch.setattr(inflight, "atomic_write", die_committing_the_9th)
    with pytest.raises(KeyboardInterrupt):
        run_calibration(config, killed, **options)
    monkeypatch.undo()
    (meta,) = (killed / "inflight").glob("*.json")
    assert meta.stem == config.cells[1].name
    assert json.loads(meta.read_text())["trainer"]["searches"]  # searches in flight
    loaded = []
    real = inflight.CellCheckpoint.load
    monkeypatch.setattr(
        inflight.CellCheckpoint, "load", lambda *a: loaded.append(r := real(*a)) or r
    )
    resumed = run_calibration(config, killed, **options)
    assert loaded[0] is not None  # the second cell continued from its checkpoint
    assert not list((killed / "inflight").iterdir())
    pd.testing.assert_frame_equal(resumed.searches, whole.searches)
    for cell in config.cells:
        ours, theirs = (
            json.loads((folder / "cells" / f"{cell.name}.json").read_text())
            for folder in (killed, tmp_path / "whole")
        )
        ours.pop("seconds"), theirs.pop("seconds")
        assert ours == theirs
        with (
            np.load(killed / "cells" / f"{cell.name}.npz") as a,
            np.load(tmp_path / "whole" / "cells" / f"{cell.name}.npz") as b,
        ):
            for key in ("theta", "omega"):
                np.testing.assert_array_equal(a[key], b[key])


def test_a_checkpoint_of_other_settings_is_refused_by_name(tmp_path, monkeypatch):
    config = tiny_study(BASE)
    options = {"progress": False, "checkpoint_seconds": 0, "check_steps": 50}
    monkeypatch.setattr(
        study, "judged_summary", lambda *a: (_ for _ in ()).throw(KeyboardInterrupt())
    )
    with pytest.raises(KeyboardInterrupt):  # killed after its last checkpoint
        run_calibration(config, tmp_path, **options)
    monkeypatch.undo()
    with pytest.raises(ValueError, match="inflight.*other settings"):
        run_calibration(dataclasses.replace(config, seed=5), tmp_path, **options)


# ------------------------------------------------------------------ the grid
def test_the_two_cart_study_grid_reads_and_its_report_writes(tmp_path):
    config = load_calibration("configs/study-two-cart.yaml")
    assert (config.seeds, config.max_steps, config.batch_size) == (4, 1_000_000, 256)
    assert config.env.n_carts == 2 and config.env == CalibrationConfig().env
    default = config.cells[0]
    assert default == Cell()  # the default cell: what the others are compared against
    kinds = {
        (c.reward, c.exploring_starts, c.continue_from, c.initial_angle) for c in config.cells[1:]
    }
    assert kinds == {
        ("height", True, "", math.pi),
        ("height-product", False, "", math.pi),
        ("height", False, default.name, math.pi),
        ("height", False, "", 0.0),  # the balance-only cell
    }
    assert config.starts == StartSpread()  # the documented default distribution
    assert config.ddpg.judge_every == 2000 == config.env.steps  # docs/study-two-cart.md
    # a tiny version of it runs end to end and writes the study's table and curves
    small = dataclasses.replace(
        config,
        seeds=2,
        max_steps=300,
        batch_size=32,
        env=dataclasses.replace(config.env, steps=60),
        ddpg=dataclasses.replace(config.ddpg, buffer_size=500, warmup_steps=100, judge_every=60),
    )
    result = run_calibration(small, tmp_path, progress=False)
    table = pd.read_csv(tmp_path / "study.csv")
    assert list(table["cell"]) == [c.name for c in config.cells]
    assert (tmp_path / "study.png").stat().st_size > 10_000
    best = pd.read_csv(tmp_path / "best_so_far.csv")
    assert set(best["aggregation"]) == {"all", "mean"}
    assert "a rod up (mean)" in (tmp_path / "calibration.md").read_text()
    # the Actors stay out of git but those the continue cell starts from (a later session's)
    kept = f"!{default.name}.npz"
    assert (tmp_path / ".gitignore").read_text().split() == ["*.npz", "inflight/", ".*.tmp", kept]
    assert len(result.searches) == 2 * len(config.cells)


def test_a_studys_docs_block_drops_the_drift_table_and_keeps_the_study_table():
    from lonlib.calibration.report import DRIFT_HEADER, calibration_block

    table = f"| cells |\n|---|\n\n{DRIFT_HEADER}\n|---|\n| euler |\n\n| study |\n|---|\n"
    block = calibration_block("data/studies/two-cart", table, "two-cart")
    assert DRIFT_HEADER not in block and "euler" not in block
    assert block.endswith("| cells |\n|---|\n\n| study |\n|---|\n")
    assert DRIFT_HEADER in calibration_block("data/calibration", table, "default")
    assert calibration_block("x", f"| cells |\n\n{DRIFT_HEADER}\n| euler |", "g").endswith(
        "| cells |\n"
    )
