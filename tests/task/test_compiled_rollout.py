"""The compiled rollout (lonlib.task.kernels) gives the bits of its numpy definition.

The numpy definition (``LONLIB_ROLLOUT=numpy``) is the oracle: portable math on hard inputs,
random Actors, starts and configurations (1-5 carts, every motor, integrator, reward and
fitness mode), batch positions, traces, the simulator's own ``step``/``observe`` (training's
env step) with ended rows, and the Gymnasium env. Then what could change the bits: no FMA
in the compiled code, another CPU target (``NUMBA_CPU_NAME=generic``), and the fallbacks.
"""

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lonlib.config import PendulumConfig
from lonlib.task import compiled
from lonlib.task.pendulum import CoupledPendulums
from lonlib.task.policy import actor_spec
from lonlib.task.rollout import perturbed_offsets, run_actors
from lonlib.util import portable_math

ROOT = Path(__file__).resolve().parents[2]
# skipped only where numba is missing: kernels that fail to compile or warm up where it is
# installed fail test_the_kernels_load_where_numba_is_installed (they used to skip this file)
HAVE_NUMBA = importlib.util.find_spec("numba") is not None
KERNELS = compiled.kernels() if HAVE_NUMBA else None
pytestmark = pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed")

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


def test_the_kernels_load_where_numba_is_installed():
    assert KERNELS is not None and compiled.backend() == "numba"


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
from lonlib.config import PendulumConfig
from tests.task.test_rollout import actors, fingerprint
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

    from lonlib.config import DDPGConfig
    from lonlib.ddpg.trainer import SlotTrainer
    from lonlib.task.policy import critic_spec

    rng = np.random.default_rng(0)
    env = PendulumConfig(n_carts=1, steps=50)
    thetas = actor_spec(1).initial(rng)[None]
    omegas = critic_spec(1).initial(rng)[None]
    for threads in (2, 1):
        SlotTrainer(thetas, omegas, [0], env, DDPGConfig(batch_size=8, threads=threads))
        assert numba.get_num_threads() == min(threads, numba.config.NUMBA_NUM_THREADS)


# --------------------------------------------------------------------- review (issue 45): the
# rare cases random episodes seldom reach, each compared with numpy directly
EDGE_VALUES = np.array(
    [0.0, -0.0, 1.0, -1.0, 0.5, -0.5, 1.5, np.nan, np.inf, -np.inf, 5e-324, -5e-324, 1e-20,
     -1e-20, 2 * np.pi, -2 * np.pi, 4 * np.pi, 7.0, -7.0]
)  # fmt: skip


def test_the_scalar_helpers_are_numpys_on_signed_zeros_nan_and_ties():
    # numpy's clip, maximum, minimum, sign and mod, value for value: a rollout reaches a
    # -0.0 velocity, a NaN state or phi = -2 pi only rarely, so random episodes miss them
    with np.errstate(all="ignore"):
        for a in EDGE_VALUES:
            assert same_bits(np.float64(KERNELS._sign(a)), np.sign(a)), a
            for low, high in ((0.0, 1.0), (-1.0, 1.0)):
                got = np.float64(KERNELS._clip(a, low, high))
                assert same_bits(got, np.clip(a, low, high)), (a, low, high)
            for b in EDGE_VALUES:
                assert same_bits(np.float64(KERNELS._maximum(a, b)), np.maximum(a, b)), (a, b)
                assert same_bits(np.float64(KERNELS._minimum(a, b)), np.minimum(a, b)), (a, b)
                if np.isfinite(b) and b != 0.0:
                    assert same_bits(np.float64(KERNELS._mod(a, b)), np.mod(a, b)), (a, b)


@pytest.mark.parametrize("n_carts", [2, 3, 5])
def test_end_reasons_on_exact_edges_and_several_rules_at_once_are_numpys(n_carts):
    # ties (a gap of exactly the tether or the width, an edge exactly at the track's end)
    # and every pair of rules in one state: collision > tether > boundary, as in numpy
    config = PendulumConfig(n_carts=n_carts)
    half, width, tether = config.track_half_length, config.cart_width, config.tether_length
    edge = half - 0.5 * width
    near = [edge, np.nextafter(edge, 0.0), np.nextafter(edge, 9.0)]
    assert any(abs(s) + 0.5 * width == half for s in near)  # an exact boundary tie
    spots = np.array(
        [*near, *(-s for s in near), 0.0, width, tether, 2 * tether, tether + width,
         np.nextafter(tether, 9.0), np.nextafter(width, 0.0), 0.5, -0.5, edge - tether]
    )  # fmt: skip
    rng = np.random.default_rng(n_carts)
    x = rng.choice(spots, size=(3000, n_carts))
    x[::2] = np.sort(x[::2], axis=1)  # in order: tether and boundary without a collision
    sim = CoupledPendulums(config, len(x))
    sim.x = x
    expected = sim._termination_reason()
    fc, ic = compiled.pack(config)
    got = np.array([KERNELS._end_reason(fc, ic, np.ascontiguousarray(row)) for row in x])
    assert np.array_equal(got, expected)
    gaps = np.diff(x, axis=1)
    assert (gaps == tether).any() and (gaps == width).any()
    boundary = (np.abs(x) + 0.5 * width > half).any(axis=1)
    assert (boundary & (gaps > tether).any(axis=1) & (gaps >= width).all(axis=1)).any()
    if n_carts > 2:
        assert ((gaps > tether).any(axis=1) & (gaps < width).any(axis=1)).any()


def crafted(config: PendulumConfig) -> CoupledPendulums:
    """States random episodes seldom reach, one per row: a cart about to leave the track,
    one rod upright and one hanging, a spinning rod, signed zeros, NaN, exact quadrants."""
    n = config.n_carts
    sim = CoupledPendulums(config, 8)
    edge = config.track_half_length - 0.5 * config.cart_width
    sim.x_dot[0, 0], sim.x[0, 0] = -3.0, -edge + 1e-3  # leaves the track on the first step
    sim.phi[1] = [0.0 if c % 2 == 0 else np.pi for c in range(n)]
    sim.phi_dot[2] = 40.0  # faster than the sensor range (slow-height's min)
    sim.x_dot[3], sim.phi_dot[3] = -0.0, -0.0
    sim.phi_dot[4, -1] = np.nan  # never ends: truncated with a NaN state
    sim.phi[5] = 0.5 * np.pi * np.arange(n)
    sim.phi[6] = 2 * np.pi - 1e-17
    sim.x[7] = sim.x[7] + 3.0  # ends by boundary (or tether) on the first step
    return sim


@pytest.mark.parametrize("steps", [1, 2, 3])
def test_crafted_states_step_and_end_with_the_numpy_bits(monkeypatch, steps):
    # terminated on the very step that reaches the step limit (terminated, not truncated),
    # ended rows stepped again (NaN reward of a NaN state), every reward and fitness mode
    actions = [0.5, np.nan, -0.0, 1.5, 0.0]
    for reward in ("height", "slow-height", "height-product", "upright"):
        for mode in ("all", "mean"):
            for n_carts in (2, 3):
                config = PendulumConfig(
                    n_carts=n_carts, steps=steps, reward=reward, fitness_mode=mode,
                    upright_angle=0.3,
                )  # fmt: skip

                def run(config=config):
                    sim = crafted(config)
                    out = []
                    with np.errstate(all="ignore"):
                        for t in range(steps + 2):
                            a = np.full(sim.x.shape, actions[t % len(actions)])
                            r = sim.step(a)
                            kept = (sim.observe(), *vars(r).values())
                            kept += tuple(getattr(sim, s) for s in sim.STATE_ARRAYS)
                            out.append(tuple(np.array(k, copy=True) for k in kept))
                    return out

                expected, got = oracle(monkeypatch, run)
                for t, (a, b) in enumerate(zip(expected, got, strict=True)):
                    for i, (u, v) in enumerate(zip(a, b, strict=True)):
                        assert same_bits(np.asarray(u), np.asarray(v)), (config, t, i)


@pytest.mark.parametrize("steps", [40, 3])
def test_traces_after_an_early_end_and_an_end_on_the_last_step_are_numpys(monkeypatch, steps):
    # row 0 leaves the track at step 3 with its rods upright (upright_angle pi), the others
    # run on: its trace repeats its frozen state, sensors, actions, no upright flag; with
    # steps = 3 it ends on the last step (boundary, not the step limit)
    config = PendulumConfig(n_carts=2, steps=steps, upright_angle=np.pi, motor="acceleration")
    edge = config.track_half_length - 0.5 * config.cart_width
    offsets = perturbed_offsets(config, 3, 0.01, seed=1)
    offsets[0, 0] = -edge - config.initial_positions()[0] + 0.05  # both carts, no tether
    offsets[1, 0] = -1.0
    thetas = actor_spec(2).initial(np.random.default_rng(5))
    expected, got = oracle(monkeypatch, lambda: run_actors(thetas, config, offsets, trace=True))
    assert_same_rollout(expected, got)
    assert got.end_step[0] == 3 and got.end_reason[0] == 4  # boundary
    assert got.end_step.max() == steps
    assert got.trace.upright[2, 0].all()  # upright on its last step


def test_a_rod_exactly_at_the_upright_angle_is_not_upright():
    # the upright test is strict (cos(phi) > cos(angle)), as in numpy: a tie is not upright
    for angle in (0.3, np.pi / 2, 3.0):
        config = PendulumConfig(n_carts=2, upright_angle=angle)
        fc, ic = compiled.pack(config)
        phi = np.array([angle, 2 * np.pi - angle])
        each = np.zeros(2, dtype=np.bool_)
        count, _ = KERNELS._rods(fc, ic, phi, np.zeros(2), each)
        expected = portable_math.cos(phi) > portable_math.cos(np.float64(angle))
        assert not expected[0]  # the tie
        assert count == expected.sum() and np.array_equal(each, expected)


def test_a_diverging_episode_raises_the_numpy_definitions_value_error(monkeypatch):
    # an angular velocity of 1e9 takes a substep's angle beyond sin/cos's 1e5: numpy's
    # ValueError, not numba's "SystemError: ... returned a result with an exception set"
    config = PendulumConfig(substeps=3, steps=50)
    offsets = perturbed_offsets(config, 2, 0.01)
    offsets[3, 0, 0] = 1e9
    thetas = actor_spec(2).initial(np.random.default_rng(0))
    for choice in ("numpy", "numba"):
        monkeypatch.setenv(compiled.ROLLOUT_VARIABLE, choice)
        with pytest.raises(ValueError, match="sin/cos arguments must lie within"):
            run_actors(thetas, config, offsets)


def test_bad_traces_and_actor_counts_are_refused_by_both_rollouts(monkeypatch):
    config = PendulumConfig(steps=20)
    thetas = np.stack([actor_spec(2).initial(np.random.default_rng(i)) for i in range(3)])
    for choice in ("numpy", "numba"):
        monkeypatch.setenv(compiled.ROLLOUT_VARIABLE, choice)
        with pytest.raises(ValueError, match="3 Actors for 5 starts"):
            run_actors(thetas, config, perturbed_offsets(config, 5, 0.01))
        with pytest.raises(ValueError, match="trace must be"):
            run_actors(thetas, config, perturbed_offsets(config, 3, 0.01), trace=-1)


def test_a_rollout_from_another_thread_uses_the_count_set_not_every_core():
    import threading

    import numba

    seen = []
    compiled.set_threads(1)

    def work():
        run_actors(actor_spec(1).initial(np.random.default_rng(0)), PendulumConfig(n_carts=1))
        seen.append(numba.get_num_threads())

    thread = threading.Thread(target=work)
    thread.start()
    thread.join()
    assert seen == [1]
