"""The one rollout: defined arithmetic (batch, position, CPU dispatch), both aggregations,
the conditioning, and that every consumer delegates to it."""

import ast
import dataclasses
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lonlib.config import PendulumConfig, Scoring
from lonlib.task.behaviour import describe, describe_actors
from lonlib.task.policy import actor_spec
from lonlib.task.rollout import nominal_offsets, perturbed_offsets, run_actors, score_actors
from lonlib.util import portable_math

SHORT = PendulumConfig(steps=300)
SPEC = actor_spec(2)
ROOT = Path(__file__).resolve().parents[2]


def actors(seed: int, k: int, scale: float = 3.0) -> np.ndarray:
    """``k`` random Actors with large weights: bang-bang policies, chaotic episodes."""
    rng = np.random.default_rng(seed)
    return (scale * np.stack([SPEC.initial(rng) for _ in range(k)])).astype(np.float32)


def fingerprint(result) -> str:
    """A hash of every number a rollout returns, trace included."""
    digest = hashlib.sha256()
    for name in ("fitness", "fitness_all", "fitness_mean", "end_reason", "end_step"):
        digest.update(np.ascontiguousarray(getattr(result, name)).tobytes())
    digest.update(result.episode_return.tobytes())
    if result.trace is not None:
        for b in range(len(result.fitness)):
            row = result.trace.row(b, int(result.end_step[b]))
            for value in (row.x, row.phi, row.phi_dot, row.actions, row.sensors):
                digest.update(np.ascontiguousarray(value).tobytes())
    return digest.hexdigest()


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**16), size=st.integers(1, 9), position=st.integers(0, 8))
def test_a_row_is_bit_identical_whatever_the_batch_and_its_position(seed, size, position):
    position = min(position, size - 1)
    theta = actors(seed, 1)[0]
    alone = run_actors(theta[None], SHORT, trace=True)
    batch = actors(seed + 1, size)
    batch[position] = theta
    together = run_actors(batch, SHORT, trace=True)
    for name in ("fitness", "fitness_all", "fitness_mean", "end_step", "episode_return"):
        assert getattr(together, name)[position] == getattr(alone, name)[0]
    mine = together.trace.row(position, int(alone.end_step[0]))
    np.testing.assert_array_equal(mine.actions, alone.trace.row(0, 10**6).actions)
    np.testing.assert_array_equal(mine.phi, alone.trace.row(0, 10**6).phi)


def test_one_shared_actor_and_one_actor_per_row_are_the_same_arithmetic():
    theta = actors(3, 1)[0]
    offsets = perturbed_offsets(SHORT, 4, 0.01, seed=5)
    shared = run_actors(theta, SHORT, offsets)
    per_row = run_actors(np.repeat(theta[None], 4, axis=0), SHORT, offsets)
    assert fingerprint(shared) == fingerprint(per_row)


DISPATCH_SCRIPT = """
import hashlib, json, numpy as np
from lonlib.config import Scoring
from lonlib.task.rollout import run_actors, score_actors
from tests.task.test_rollout import actors, fingerprint, SHORT
result = run_actors(actors(11, 6), SHORT, trace=True)
scores = score_actors(actors(12, 3), SHORT, Scoring(estimate="robust", starts=4))
x = np.random.default_rng(0).normal(0, 5, 10001).astype(np.float32)
print(json.dumps({
    "rollout": fingerprint(result),
    "robust": scores.fitness.tolist() + scores.robust_std.tolist(),
    "np_tanh": hashlib.sha256(np.tanh(x).tobytes()).hexdigest(),
}))
"""


def run_with(env: dict[str, str]) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", DISPATCH_SCRIPT],
        env={**os.environ, "PYTHONPATH": str(ROOT), **env},
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_rollout_does_not_depend_on_numpy_dispatch_or_glibc_fma():
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    baseline = run_with({})
    disabled = run_with(
        {
            "NPY_DISABLE_CPU_FEATURES": " ".join(__cpu_dispatch__),
            "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-FMA4,-AVX512F,-AVX",
        }
    )
    assert disabled["rollout"] == baseline["rollout"]
    assert disabled["robust"] == baseline["robust"]
    if __cpu_features__.get("AVX2") and __cpu_features__.get("FMA3"):
        # the switch took effect: numpy's own float32 tanh changed its bits
        assert disabled["np_tanh"] != baseline["np_tanh"]


def test_portable_math_is_accurate():
    x = np.random.default_rng(0).uniform(-30, 30, 100_000)
    np.testing.assert_allclose(portable_math.exp(x), np.exp(x), rtol=4e-16)
    y = np.random.default_rng(1).uniform(-20, 20, 100_000)
    sin, cos = portable_math.sin_cos(y)
    np.testing.assert_allclose(sin, np.sin(y), rtol=0, atol=5e-16)
    np.testing.assert_allclose(cos, np.cos(y), rtol=0, atol=5e-16)
    assert portable_math.sigmoid(np.array([-800.0, 0.0, 800.0])).tolist() == [
        pytest.approx(0.0, abs=1e-300),
        0.5,
        1.0,
    ]


def test_both_aggregations_come_from_one_episode():
    config = PendulumConfig(n_carts=2, steps=200, initial_angle=0.3)  # rods fall from the top
    result = run_actors(actors(21, 12, 1.0), config, trace=True)
    assert (result.fitness_mean > result.fitness_all).any() and (result.fitness_all > 0).any()
    for b in range(12):
        row = result.trace.row(b, int(result.end_step[b]))
        assert result.fitness_all[b] == row.upright.all(axis=1).sum() / config.steps
        assert result.fitness_mean[b] == pytest.approx(row.upright.mean(axis=1).sum() / 200)
    assert (result.fitness_mean >= result.fitness_all).all()
    assert (result.fitness == result.fitness_all).all()  # fitness_mode "all" by default


def test_robust_scores_use_the_same_perturbed_starts_for_every_policy():
    thetas = actors(31, 3)
    scoring = Scoring(estimate="robust", starts=5, noise=0.02, seed=7)
    scores = score_actors(thetas, SHORT, scoring)
    offsets = perturbed_offsets(SHORT, 5, 0.02, seed=7)
    for b in range(3):
        alone = run_actors(thetas[b], SHORT, offsets)
        assert scores.robust_min[b] == alone.fitness.min()
        assert scores.fitness[b] == scores.robust_mean[b]
        assert scores.robust_mean[b] == pytest.approx(alone.fitness.mean(), abs=1e-15)
    nominal = score_actors(thetas, SHORT, Scoring())
    np.testing.assert_array_equal(nominal.fitness, scores.nominal.fitness)
    assert nominal.robust_mean is None
    assert (nominal_offsets(SHORT) == 0).all()


def test_the_descriptor_describes_the_scored_episode():
    config = PendulumConfig(steps=300, initial_angle=0.3)  # rods start near the top: f > 0
    thetas = actors(41, 4, 1.0)
    scoring = Scoring(starts=3)
    scores = score_actors(thetas, config, scoring, conditioning=True)
    many = describe_actors(thetas, config, scoring)
    assert (scores.fitness > 0).all() and (scores.nominal.fitness_mean > scores.fitness).any()
    for b in range(4):
        one = describe(thetas[b], config, scoring)
        assert one == many[b]
        assert one.fitness == scores.fitness[b] and one.robust_mean == scores.robust_mean[b]
        assert one.fitness_mean == scores.nominal.fitness_mean[b]
        assert one.fitness_all <= one.end_step / config.steps
        assert one.robust_std == scores.robust_std[b]


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("estimate", "luckiest", "fitness_estimate"),
        ("starts", 0, "robust_starts"),
        ("noise", -0.1, "robust_noise"),
    ],
)
def test_bad_scoring_is_refused_by_name(field, value, message):
    with pytest.raises(ValueError, match=message):
        Scoring(**{field: value})


def test_bad_actors_are_refused_before_any_compute():
    with pytest.raises(ValueError, match="shape"):
        run_actors(np.zeros((2, 10)), SHORT)
    bad = actors(1, 1)
    bad[0, 5] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        run_actors(bad, SHORT)


# Modules allowed to step the simulator in a loop: the rollout, and DDPG's training (its
# SlotTrainer steps once per call; the loop over training steps calls the trainer).
STEPPERS = {"rollout.py"}


def loops_stepping_a_simulator(path: Path) -> list[int]:
    """Lines of loops in ``path`` whose body calls ``<something named sim>.step(...)``."""
    lines = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not isinstance(node, (ast.For, ast.While)):
            continue
        for inner in ast.walk(node):
            if (
                isinstance(inner, ast.Call)
                and isinstance(inner.func, ast.Attribute)
                and inner.func.attr == "step"
                and "sim" in ast.unparse(inner.func.value).lower()
            ):
                lines.append(node.lineno)
    return lines


def test_no_module_but_the_rollout_steps_the_simulator_in_a_loop():
    offenders = {
        str(path.relative_to(ROOT)): loops_stepping_a_simulator(path)
        for path in sorted((ROOT / "lonlib").rglob("*.py"))
        if path.name not in STEPPERS
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_the_delegation_check_sees_a_loop_that_steps_a_simulator(tmp_path):
    module = tmp_path / "sneaky.py"
    module.write_text("def f(sim, policy):\n    while True:\n        sim.step(policy(1))\n")
    assert loops_stepping_a_simulator(module) == [2]


def test_every_entry_point_scores_from_the_same_noisy_start():
    """With start noise, evaluate(seed=s), score_actors, describe, DDPG's scoring and a
    recording all start from the nominal start drawn from eval_seed s, and another seed
    gives another start."""
    import tempfile

    from lonlib.analysis.recordings import record, recording_properties
    from lonlib.config import DDPGConfig
    from lonlib.task.rollout import actor_policy, evaluate

    config = PendulumConfig(steps=300, initial_angle=0.3, initial_noise=0.2)
    thetas = actors(51, 3, 1.0)
    scoring = DDPGConfig(eval_seed=3).scoring
    assert scoring.eval_seed == 3
    scored = score_actors(thetas, config, scoring).fitness
    by_evaluate = evaluate(actor_policy(thetas, config), config, 3, seed=3, same_start=True)
    np.testing.assert_array_equal(by_evaluate.fitness, scored)
    assert describe(thetas[0], config, scoring).fitness == scored[0]
    other = score_actors(thetas, config, Scoring(eval_seed=4)).fitness
    assert not np.array_equal(other, scored)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "x.rrd"
        record(thetas[0], config, path, scoring=scoring)
        assert recording_properties(path)["fitness"] == scored[0]


@pytest.mark.parametrize("field", ["seed", "eval_seed"])
def test_negative_seeds_are_refused_by_name(field):
    from lonlib.config import DDPGConfig

    with pytest.raises(ValueError, match="seed"):
        Scoring(**{field: -1})
    name = "robust_seed" if field == "seed" else "eval_seed"
    with pytest.raises(ValueError, match=name):
        DDPGConfig(**{name: -1})


@pytest.mark.parametrize("estimate", ["nominal", "robust"])
def test_a_traced_scoring_keeps_every_number_and_traces_the_nominal_episodes(estimate):
    thetas = actors(31, 4)
    scoring = Scoring(estimate=estimate, starts=3)
    plain, traced = (
        score_actors(thetas, SHORT, scoring),
        score_actors(thetas, SHORT, scoring, trace=True),
    )
    assert plain.nominal.trace is None
    np.testing.assert_array_equal(plain.fitness, traced.fitness)
    assert fingerprint(plain.nominal) == fingerprint(
        dataclasses.replace(traced.nominal, trace=None)
    )
    alone = run_actors(thetas, SHORT, trace=True)  # each Actor's nominal episode, traced
    assert fingerprint(traced.nominal) == fingerprint(alone)
