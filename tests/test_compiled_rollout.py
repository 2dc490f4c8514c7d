"""The compiled rollout (lonlib.task.kernels) gives the bits of its numpy definition.

The numpy definition (``LONLIB_ROLLOUT=numpy``) is the oracle: portable math on hard inputs,
random Actors, starts and configurations (1-5 carts, every motor, integrator, reward and
fitness mode), batch positions, traces, the simulator's own ``step``/``observe`` (training's
env step) with ended rows, and the Gymnasium env. Then what could change the bits: no FMA
in the compiled code, another CPU target (``NUMBA_CPU_NAME=generic``), and the fallbacks.
"""

import os
import subprocess
import sys
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lonlib.task import compiled
from lonlib.task.pendulum import CoupledPendulums, PendulumConfig
from lonlib.task.policy import actor_spec
from lonlib.task.rollout import perturbed_offsets, run_actors
from lonlib.util import portable_math

ROOT = Path(__file__).resolve().parents[1]
KERNELS = compiled.kernels()
pytestmark = pytest.mark.skipif(KERNELS is None, reason="numba is not installed")

ROLLOUT_FIELDS = ("fitness", "fitness_all", "fitness_mean", "end_reason", "end_step")
TRACE_FIELDS = ("x", "x_dot", "phi", "phi_dot", "sensors", "actions", "upright", "fitness")


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal shapes and bytes (so -0.0 differs from 0.0 and NaN equals the same NaN)."""
    a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def oracle(monkeypatch, call):
    """``call()`` on the numpy definition, then on the kernels."""
    monkeypatch.setenv(compiled.ROLLOUT_VARIABLE, "numpy")
    expected = call()
    monkeypatch.setenv(compiled.ROLLOUT_VARIABLE, "numba")
    return expected, call()


def assert_same_rollout(expected, got) -> None:
    for name in (*ROLLOUT_FIELDS, "episode_return"):
        assert same_bits(getattr(expected, name), getattr(got, name)), name
    assert (expected.trace is None) == (got.trace is None)
    if expected.trace is not None:
        for name in TRACE_FIELDS:
            assert same_bits(getattr(expected.trace, name), getattr(got.trace, name)), name


HARD = np.array(
    [0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, -1e-310, 1e-300, np.nan, np.inf,
     -np.inf, 1e300, -1e300, 708.0, -708.0, 709.5, -745.2, 1e5, -1e5, 99999.9, 0.5, -0.5,
     np.pi / 4, 3 * np.pi / 4, -np.pi, 2 * np.pi, 710.0, 1e-17, 12345.678]
)  # fmt: skip


def test_portable_math_matches_on_zeros_subnormals_nan_and_huge_inputs():
    for x in HARD:
        assert same_bits(KERNELS.exp(x), portable_math.exp(x)), x
        assert same_bits(KERNELS.sigmoid(x), portable_math.sigmoid(x)), x
        if not abs(x) > 1e5:
            sin, cos = portable_math.sin_cos(x)
            got = KERNELS.sin_cos(x)
            assert same_bits(got[0], sin) and same_bits(got[1], cos), x
    with pytest.raises(ValueError, match="1e\\+05"):
        KERNELS.sin_cos(1e6)


@settings(max_examples=60, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True, width=64))
def test_portable_math_matches_on_any_float(x):
    assert same_bits(KERNELS.exp(x), portable_math.exp(x))
    assert same_bits(KERNELS.sigmoid(x), portable_math.sigmoid(x))
    if not abs(x) > 1e5:
        sin, cos = portable_math.sin_cos(x)
        got = KERNELS.sin_cos(x)
        assert same_bits(got[0], sin) and same_bits(got[1], cos)


configs = st.builds(
    PendulumConfig,
    n_carts=st.integers(1, 5),
    motor=st.sampled_from(["force", "acceleration", "velocity"]),
    integrator=st.sampled_from(["euler", "semi-implicit"]),
    reward=st.sampled_from(["height", "slow-height", "height-product", "upright"]),
    fitness_mode=st.sampled_from(["all", "mean"]),
    substeps=st.integers(1, 3),
    motor_tau=st.sampled_from([0.02, 0.1]),
    motor_gain=st.sampled_from([0.5, 1.0, 5.0]),
    upright_angle=st.sampled_from([np.pi / 2, 0.3, np.pi]),
    initial_angle=st.sampled_from([np.pi, 0.0, 3.0]),
    steps=st.integers(1, 150),
)


@settings(max_examples=25, deadline=None)
@given(config=configs, seed=st.integers(0, 2**16), rows=st.integers(1, 6), scale=st.floats(0.5, 8))
def test_random_actors_starts_and_configs_give_the_numpy_bits(config, seed, rows, scale):
    monkeypatch = pytest.MonkeyPatch()
    rng = np.random.default_rng(seed)
    spec = actor_spec(config.n_carts)
    thetas = (scale * np.stack([spec.initial(rng) for _ in range(rows)])).astype(np.float32)
    offsets = perturbed_offsets(config, rows, 0.05, seed=seed)
    with monkeypatch.context() as patch:
        expected, got = oracle(patch, lambda: run_actors(thetas, config, offsets, trace=rows // 2))
    assert_same_rollout(expected, got)


def test_a_shared_actor_and_a_row_in_any_position_give_the_numpy_bits(monkeypatch):
    config = PendulumConfig(steps=400)
    rng = np.random.default_rng(7)
    thetas = (4 * np.stack([actor_spec(2).initial(rng) for _ in range(9)])).astype(np.float32)
    offsets = perturbed_offsets(config, 9, 0.01, seed=3)
    expected, got = oracle(monkeypatch, lambda: run_actors(thetas[4], config, offsets, trace=9))
    assert_same_rollout(expected, got)
    expected, got = oracle(monkeypatch, lambda: run_actors(thetas, config, trace=True))
    assert_same_rollout(expected, got)


def drive(sim: CoupledPendulums, steps: int, seed: int) -> list:
    """Step ``sim`` with random actions, resetting a few ended rows: every output kept."""
    rng = np.random.default_rng(seed)
    kept = []
    for t in range(steps):
        observation = sim.observe()
        actions = rng.uniform(-0.2, 1.2, size=sim.x.shape)  # clipped by the step
        outcome = sim.step(actions)
        kept.append(
            (observation, outcome.reward, outcome.upright, outcome.upright_each,
             outcome.terminated, outcome.truncated, outcome.end_reason,
             *(getattr(sim, name).copy() for name in CoupledPendulums.STATE_ARRAYS))
        )  # fmt: skip
        if t % 17 == 16:
            sim.reset(mask=sim.done & (rng.uniform(size=sim.batch_size) < 0.5))
    return kept


@settings(max_examples=12, deadline=None)
@given(config=configs, seed=st.integers(0, 2**16), batch=st.integers(1, 7))
def test_the_simulators_step_and_observe_give_the_numpy_bits_with_ended_rows(config, seed, batch):
    def run():
        sim = CoupledPendulums(config, batch, seed=seed)
        return drive(sim, 120, seed)

    with pytest.MonkeyPatch().context() as patch:
        expected, got = oracle(patch, run)
    for t, (a, b) in enumerate(zip(expected, got, strict=True)):
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert same_bits(np.asarray(x), np.asarray(y)), (t, i)


def test_the_gymnasium_env_steps_through_the_kernels_with_the_numpy_bits(monkeypatch):
    def episode():
        env = gymnasium.make("lonlib/CoupledPendulum-v1", max_episode_steps=300)
        obs, _ = env.reset(seed=0)
        rng = np.random.default_rng(0)
        out = [obs]
        for _ in range(300):
            obs, reward, terminated, truncated, info = env.step(
                rng.uniform(0, 1, 2).astype(np.float32)
            )
            out += [obs, np.float64(reward), np.float64(info["upright"])]
            if terminated or truncated:
                break
        return out

    expected, got = oracle(monkeypatch, episode)
    assert len(expected) == len(got) > 10
    assert all(same_bits(np.asarray(a), np.asarray(b)) for a, b in zip(expected, got, strict=True))


FMA_SCRIPT = """
import json
from lonlib.task import compiled
kernels = compiled.kernels()
kernels.exp(0.5), kernels.sin_cos(0.5), kernels.sigmoid(0.5)
found = {}
for name in ("rollout", "step_batch", "observe_batch", "exp", "sin_cos", "sigmoid"):
    text = "".join(getattr(kernels, name).inspect_asm().values())
    fused = sum(text.count(op) for op in ("vfmadd", "vfmsub", "vfnmadd", "vfnmsub"))
    found[name] = [len(text), fused]
found["backend"] = compiled.backend()
print(json.dumps(found))
"""


def test_the_compiled_code_has_no_fused_multiply_add(tmp_path):
    # compiled afresh, for this CPU: without a writable cache folder the kernels still load
    # (and code loaded from a cache cannot be inspected)
    blocker = tmp_path / "file"
    blocker.write_text("no cache")
    found = run_script(
        {compiled.CACHE_VARIABLE: str(blocker), compiled.ROLLOUT_VARIABLE: "numba"}, FMA_SCRIPT
    )
    assert found.pop("backend") == "numba"
    assert all(size > 1000 for size, _ in found.values()), found
    assert all(fused == 0 for _, fused in found.values()), found


SCRIPT = """
import json, numpy as np
from lonlib.task import compiled
from lonlib.task.rollout import run_actors, perturbed_offsets
from lonlib.task.pendulum import PendulumConfig
from tests.test_rollout import actors, fingerprint
config = PendulumConfig(steps=300, motor="force", integrator="euler")
result = run_actors(actors(11, 6), config, perturbed_offsets(config, 6, 0.05), trace=True)
print(json.dumps({"backend": compiled.backend(), "rollout": fingerprint(result)}))
"""


def run_script(env: dict[str, str], script: str = SCRIPT) -> dict:
    import json

    out = subprocess.run(
        [sys.executable, "-c", script],
        env={**os.environ, "PYTHONPATH": str(ROOT), **env},
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_generic_cpu_target_gives_the_same_bits_as_numpy():
    generic = run_script({"NUMBA_CPU_NAME": "generic", compiled.ROLLOUT_VARIABLE: "numba"})
    numpy = run_script({compiled.ROLLOUT_VARIABLE: "numpy"})
    assert generic["backend"] == "numba" and numpy["backend"] == "numpy"
    assert generic["rollout"] == numpy["rollout"]


def test_without_numba_the_numpy_rollout_runs_with_one_warning():
    script = (
        "import sys, warnings; sys.modules['numba'] = None\n"
        "warnings.simplefilter('error')\n"
        "try:\n"
        "    from lonlib.task import compiled; compiled.kernels()\n"
        "except RuntimeWarning as w: print('WARNED', w)\n"
        "warnings.simplefilter('ignore')\n" + SCRIPT
    )
    out = subprocess.run(
        [sys.executable, "-c", script],
        env={**os.environ, "PYTHONPATH": str(ROOT), compiled.ROLLOUT_VARIABLE: ""},
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert "WARNED lonlib runs the numpy rollout" in out
    assert '"backend": "numpy"' in out


def test_lonlib_rollout_numba_is_an_error_when_numba_is_missing():
    script = (
        "import sys; sys.modules['numba'] = None\n"
        "from lonlib.task import compiled\ncompiled.kernels()"
    )
    out = subprocess.run(
        [sys.executable, "-c", script],
        env={**os.environ, "PYTHONPATH": str(ROOT), compiled.ROLLOUT_VARIABLE: "numba"},
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert out.returncode != 0 and "LONLIB_ROLLOUT=numba" in out.stderr


def test_a_bad_rollout_choice_is_refused_by_name(monkeypatch):
    monkeypatch.setenv(compiled.ROLLOUT_VARIABLE, "cuda")
    with pytest.raises(ValueError, match="LONLIB_ROLLOUT must be one of"):
        run_actors(actor_spec(1).initial(np.random.default_rng(0)), PendulumConfig(n_carts=1))


def test_the_cache_folder_is_keyed_by_version_and_kernel_sources(tmp_path, monkeypatch):
    monkeypatch.setenv(compiled.CACHE_VARIABLE, str(tmp_path))
    folder = compiled.cache_folder()
    from lonlib import __version__

    assert compiled.package_version() == __version__
    assert folder == tmp_path / "numba" / f"{__version__}-{compiled.source_hash()}"
    assert folder.is_dir()


def test_importing_lonlib_and_its_analysis_does_not_import_numba():
    script = (
        "import sys, lonlib, lonlib.analysis, lonlib.storage, lonlib.cli\n"
        "print('numba' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", script],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    assert out.stdout.strip().splitlines()[-1] == "False"


def test_training_rollouts_use_torchs_threads_on_the_cpu_never_more():
    import numba

    from lonlib.ddpg import DDPGConfig
    from lonlib.ddpg.trainer import SlotTrainer
    from lonlib.task.policy import critic_spec

    rng = np.random.default_rng(0)
    env = PendulumConfig(n_carts=1, steps=50)
    thetas = actor_spec(1).initial(rng)[None]
    omegas = critic_spec(1).initial(rng)[None]
    for threads in (2, 1):
        SlotTrainer(thetas, omegas, [0], env, DDPGConfig(batch_size=8, threads=threads))
        assert numba.get_num_threads() == min(threads, numba.config.NUMBA_NUM_THREADS)
