"""The hold test (issue 46): the imitation Actor replays its committed score, the pair
teacher balances two carts, the pre-registered verdict, and a tiny hold test end to end
(resume never redoes a search, drain starts no new one)."""

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

import lonlib.calibration.hold as hold
from lonlib.calibration.hold import HoldTest, HoldTestConfig, held, judged_measures, summarise
from lonlib.calibration.imitation import DEFAULT_TEACHER, load_teacher, pair_teacher
from lonlib.cli import main
from lonlib.config import PendulumConfig
from lonlib.task import nominal_offsets, run_actors, run_policy

ROOT = Path(__file__).resolve().parents[2]
ACTOR_FOLDER = ROOT / "data" / "studies" / "hold-test"


def test_the_committed_imitation_actor_replays_its_score_exactly():
    theta = np.load(ACTOR_FOLDER / "actor.npy")
    record = json.loads((ACTOR_FOLDER / "actor.json").read_text())
    assert theta.dtype == np.float32 and theta.shape == (1302,)
    rollout = run_actors(theta, PendulumConfig())
    assert float(rollout.fitness[0]) == record["fitness"]
    assert float(rollout.fitness_mean[0]) == record["fitness_mean"]
    assert int(rollout.end_step[0]) == record["end_step"]
    assert record["fitness"] >= 0.97
    assert record["config"]["seed"] == 0 and "--seed 0" in record["command"]


def test_a_one_cart_optimum_copied_to_both_carts_balances_both_rods():
    """Each copy reads the pair's other outer proximity sensor in its inner slot: the pair
    moves as one cart and scores the one-cart optimum's fitness on two carts."""
    theta = load_teacher(ROOT / DEFAULT_TEACHER)
    one, two = PendulumConfig(n_carts=1), PendulumConfig()
    alone = run_actors(theta, one)
    pair = run_policy(pair_teacher(theta, two), two, nominal_offsets(two))
    assert float(alone.fitness[0]) >= 0.976
    assert float(pair.fitness[0]) == float(alone.fitness[0])


def test_the_verdict_follows_the_pre_registered_rule():
    config = HoldTestConfig()  # 4 seeds, holds at >= 3 with last judged >= 0.9
    assert (config.seeds, config.hold_seeds, config.hold_fitness) == (4, 3, 0.9)
    assert held([0.95, 0.9, 0.2, 0.977], config) is True  # 0.9 itself counts
    assert held([0.95, 0.89, 0.2, 0.977], config) is False
    assert held([0.95, 0.95, 0.95], config) is True  # decided before the fourth seed
    assert held([0.1, 0.2], config) is False  # two failures of four: cannot reach three
    assert held([0.95, 0.2], config) is None
    assert held([float("nan"), 0.95, 0.95, 0.95], config) is True


def _record(arm, p, seed, last, late=None, label="balancing", returned=0.977):
    return {
        "arm": arm,
        "p": p,
        "seed_index": seed,
        "last_judged_fitness": last,
        "late_share": late,
        "last_judged_label": label,
        "returned_fitness": returned,
    }


def test_the_summary_applies_the_rule_per_arm_and_p():
    config = HoldTestConfig()
    records = [_record("fresh", 1e-4, i, f) for i, f in enumerate([0.97, 0.96, 0.0, 0.91])]
    records += [_record("fresh", 1e-3, i, f, label="crash") for i, f in enumerate([0.97, 0.1, 0.0])]
    records += [_record("control", 1e-4, 0, 0.977, late=0.5)]
    summary = summarise(records, config).set_index(["arm", "p"])
    assert summary.loc[("fresh", 1e-4), "held"] == "held"
    assert summary.loc[("fresh", 1e-4), "held_seeds"] == 3
    assert summary.loc[("fresh", 1e-3), "held"] == "not held"
    assert summary.loc[("fresh", 1e-3), "labels_at_end"] == "crash x3"
    assert summary.loc[("control", 1e-4), "held"] == "pending"
    assert summary.loc[("control", 1e-4), "late_share_mean"] == 0.5
    assert summary.loc[("fitted", 1e-4), "seeds_done"] == 0
    assert summary.loc[("fitted", 1e-4), "held"] == "pending"


def test_judged_measures_take_the_last_judged_policy_and_the_late_share():
    config = HoldTestConfig(late_steps=100)
    m = judged_measures(
        [50, 90, 150, 200, 260],
        [0.97, 0.95, 0.1, 0.92, 0.3],
        ["balancing", "balancing", "crash", "balancing", "spinning"],
        config,
    )
    assert m["last_judged_fitness"] == 0.3 and m["last_judged_label"] == "spinning"
    assert m["last_judged_steps"] == 260
    assert m["late_judged"] == 3 and m["late_share"] == pytest.approx(1 / 3)
    empty = judged_measures([], [], [], config)
    assert empty["last_judged_fitness"] is None and empty["late_share"] is None


TINY = {
    "perturbations": [1e-3],
    "seeds": 1,
    "hold_seeds": 1,
    "critic_fit_steps": 120,
    "late_steps": 100,
    "ddpg": {
        "batch_size": 16,
        "buffer_size": 1000,
        "warmup_steps": 60,
        "max_steps": 200,
        "min_steps": 200,
        "patience_steps": 200,
    },
}


def _tiny(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.yaml"
    values = dict(TINY, actor=str(ACTOR_FOLDER / "actor.npy"), control=str(ROOT / DEFAULT_TEACHER))
    path.write_text(yaml.safe_dump(values))
    return path


def test_a_tiny_hold_test_runs_end_to_end_and_resumes_without_redoing(tmp_path, monkeypatch):
    config_path, out = _tiny(tmp_path), tmp_path / "hold"
    main(["hold-test", str(out), "--config", str(config_path), "--quiet"])
    names = sorted(p.stem for p in (out / "searches").glob("*.json"))
    assert names == ["control_p=0.001_seed=0", "fitted_p=0.001_seed=0", "fresh_p=0.001_seed=0"]
    record = json.loads((out / "searches" / "fresh_p=0.001_seed=0.json").read_text())
    assert record["env_steps"] == 200 and record["n_carts"] == 2
    assert record["judged"] == len(record["judged_fitness"]) == len(record["judged_label"])
    if record["judged"]:
        assert record["last_judged_fitness"] == record["judged_fitness"][-1]
    control = json.loads((out / "searches" / "control_p=0.001_seed=0.json").read_text())
    assert control["n_carts"] == 1
    with np.load(out / "fitted_critic.npz") as data:
        assert data["omega"].shape == (1321,)
        assert bool(data["actor_unchanged"])  # the Actor stayed frozen
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary["arm"]) == ["fresh", "fitted", "control"]
    assert set(summary["held"]) <= {"held", "not held"}
    assert "Pre-registered" in (out / "summary.md").read_text()
    assert not list((out / "inflight").glob("*")) if (out / "inflight").exists() else True

    monkeypatch.setattr(HoldTest, "run_search", lambda *a, **k: pytest.fail("redone"))
    monkeypatch.setattr(hold, "fit_critic", lambda *a, **k: pytest.fail("refitted"))
    main(["hold-test", str(out), "--config", str(config_path), "--quiet"])
    assert pd.read_csv(out / "summary.csv").equals(summary)


def test_a_drained_hold_test_starts_no_new_search_and_continues(tmp_path, monkeypatch):
    config = HoldTestConfig.from_mapping(yaml.safe_load(_tiny(tmp_path).read_text()))
    ran = []

    def fake(self, spec, checkpoint_seconds=600.0, progress=False):
        ran.append(spec.name)
        record = {
            **_record(spec.arm, spec.p, spec.seed_index, 0.95),
            "name": spec.name,
            "env_steps": 1,
        }
        (self.searches).mkdir(parents=True, exist_ok=True)
        (self.paths(spec)[0]).write_text(json.dumps(record))
        return record

    monkeypatch.setattr(HoldTest, "run_search", fake)
    test = HoldTest(config, tmp_path / "out")
    _, done = test.run(drain_after_seconds=0.0)
    assert ran == ["fresh_p=0.001_seed=0"] and not done  # at least one, then no new one
    _, done = test.run()
    assert ran == ["fresh_p=0.001_seed=0", "fitted_p=0.001_seed=0", "control_p=0.001_seed=0"]
    assert done


def test_a_folder_of_other_settings_is_refused(tmp_path):
    config = HoldTestConfig.from_mapping(yaml.safe_load(_tiny(tmp_path).read_text()))
    HoldTest(config, tmp_path / "out").check_settings()
    other = HoldTestConfig.from_mapping({**yaml.safe_load(_tiny(tmp_path).read_text()), "seed": 1})
    with pytest.raises(ValueError, match="other settings"):
        HoldTest(other, tmp_path / "out").check_settings()


def test_bad_settings_are_refused_by_name():
    with pytest.raises(ValueError, match="arms"):
        HoldTestConfig(arms=("fresh", "greedy"))
    with pytest.raises(ValueError, match="hold_seeds"):
        HoldTestConfig(seeds=2, hold_seeds=3)
    with pytest.raises(ValueError, match="max_step"):
        HoldTestConfig.from_mapping({"ddpg": {"max_step": 3}})
    assert math.isclose(HoldTestConfig().ddpg.batch_size, 2000)
    assert HoldTestConfig().ddpg.max_steps == 150_000
