"""The result path's golden test (lonlib.storage.result_path) and what each session records
about where its results came from (lonlib.storage.manifest, lonlib.storage.provenance,
lonlib.util.cpu_kernels)."""

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lonlib.config import DDPGConfig, ExperimentConfig, named_config
from lonlib.experiment import run_experiment
from lonlib.storage.atomic import read_json
from lonlib.storage.manifest import (
    capability_change,
    manifest_path,
    sessions_with_other_result_path,
)
from lonlib.storage.result_path import RESULT_PATH_VERSION, experiment_digest
from lonlib.util.cpu_kernels import (
    CpuKernelWarning,
    expected_torch_capability,
    torch_cpu_capability,
    unpinned_message,
)

REPO = Path(__file__).resolve().parents[2]
CPU_FEATURES = np._core._multiarray_umath.__cpu_features__  # numpy >= 2

# experiment_digest of GOLDEN_CONFIG's experiment, sampled by RESULT_PATH_VERSION "2" with
# torch's AVX2 CPU kernels (the ones lonlib pins).
GOLDEN_DIGEST = "d220c666201d45141efa4a63c93fcae83967e921936249105c33f3798f934b1b"
BUMP = (
    "if this change is intended to alter results, bump RESULT_PATH_VERSION "
    "(lonlib/storage/result_path.py) and update the golden hash (GOLDEN_DIGEST in "
    "tests/storage/test_result_path.py)"
)

# The quick configuration's physics (two carts, the calibrated defaults) with tiny budgets:
# episodes of 60 steps, local searches of 200 env steps, up to 3 per run; "upright" within
# 2.9 rad of the top, so that fitness varies (0.2 to 0.8) and trials are rejected too.
GOLDEN_CONFIG = dataclasses.replace(
    named_config("quick"),
    name="golden",
    runs=2,
    tolerance=2,
    max_local_searches=3,
    env=dataclasses.replace(named_config("quick").env, steps=60, upright_angle=2.9),
    # written out (not tests.conftest.tiny_ddpg): the golden input never follows shared settings
    ddpg=DDPGConfig(
        batch_size=32,
        buffer_size=500,
        warmup_steps=50,
        max_steps=200,
        min_steps=0,
        patience_steps=1000,
    ),
    executor="serial",
)


def pinned_kernels_or_skip() -> None:
    """The golden numbers are defined for torch's AVX2 kernels (x86-64 with AVX2)."""
    capability = torch_cpu_capability()
    if capability != expected_torch_capability() or capability is None:
        pytest.skip(f"the golden digest is for torch's AVX2 kernels; this process: {capability}")


def test_a_tiny_experiment_stores_the_golden_numbers_serially_and_in_lockstep(tmp_path):
    pinned_kernels_or_skip()
    run_experiment(GOLDEN_CONFIG, tmp_path / "serial", progress=False)
    digest = experiment_digest(tmp_path / "serial")
    assert digest == GOLDEN_DIGEST, f"{BUMP}; the tiny experiment's digest is now {digest}"
    run_experiment(GOLDEN_CONFIG, tmp_path / "lockstep", progress=False, executor="lockstep")
    assert experiment_digest(tmp_path / "lockstep") == digest  # a run's trials: any executor


def test_the_digest_sees_a_last_bit_change_in_any_stored_number(tmp_path):
    run = tmp_path / "p=0.001" / "run_0000"
    run.mkdir(parents=True)
    trials = pd.DataFrame({"fitness": [0.25, 0.5], "label": ["crash", "spin"], "seconds": [1, 2]})
    trials.to_parquet(run / "trials.parquet")
    np.savez(run / "optimum_0000.npz", theta=np.ones(3, np.float32), omega=np.ones(2, np.float32))
    before = experiment_digest(tmp_path)
    trials.assign(seconds=[5.0, 6.0]).to_parquet(run / "trials.parquet")  # wall time only
    assert experiment_digest(tmp_path) == before
    trials.assign(fitness=[0.25, np.nextafter(0.5, 1)]).to_parquet(run / "trials.parquet")
    assert experiment_digest(tmp_path) != before
    trials.to_parquet(run / "trials.parquet")
    theta = np.ones(3, np.float32)
    theta[2] = np.nextafter(theta[2], np.float32(2))
    np.savez(run / "optimum_0000.npz", theta=theta, omega=np.ones(2, np.float32))
    assert experiment_digest(tmp_path) != before


def test_the_reference_experiment_replays_bit_for_bit_under_the_pinned_kernels():
    """The committed reference was sampled with torch's AVX2 kernels: its first local
    search replays here episode for episode (under AVX-512 the first reference, version
    "1", parted at episode 4). Skipped where the committed reference was sampled by another
    result-path version than this code's."""
    pinned_kernels_or_skip()
    from lonlib.ddpg import local_search
    from lonlib.experiment.runs import initial_parameters
    from lonlib.search.algorithm import BasinHoppingRun

    out = REPO / "data" / "reference"
    first = out / "p=0.001" / "run_0000" / "history_0000.parquet"
    if not first.exists() or sessions_with_other_result_path(out):
        pytest.skip(f"no committed reference sampled by result-path version {RESULT_PATH_VERSION}")
    config = ExperimentConfig.from_mapping(read_json(manifest_path(out))["config"])
    hp = dataclasses.replace(config.ddpg, max_steps=2500, min_steps=0)
    p, run = 1e-3, 0
    driver = BasinHoppingRun(
        initial_parameters(config, p, run), config.basin_hopping(p), config.run_seed(p, run), None
    )
    request = driver.next_search()
    result = local_search(request.theta, request.omega, config.env, hp, request.seed)
    mine = pd.DataFrame([dataclasses.asdict(r) for r in result.history]).drop(columns="seconds")
    stored = pd.read_parquet(out / "p=0.001" / "run_0000" / "history_0000.parquet")
    stored = stored.drop(columns="seconds").iloc[: len(mine) - 1]  # the slice cuts the last
    assert len(stored) >= 10
    pd.testing.assert_frame_equal(mine.iloc[: len(stored)], stored, check_exact=True)


def test_each_session_records_result_path_lock_and_cpu_kernels(tmp_path):
    config = dataclasses.replace(GOLDEN_CONFIG, runs=1, max_local_searches=1)
    run_experiment(config, tmp_path, progress=False)
    run_experiment(dataclasses.replace(config, runs=2), tmp_path, progress=False)
    sessions = read_json(manifest_path(tmp_path))["sessions"]
    assert len(sessions) == 2
    for session in sessions:
        assert session["result_path_version"] == RESULT_PATH_VERSION
        environment = session["environment"]
        assert environment["source"] in {"lock", "installed"}
        assert len(environment["sha256"]) == len(environment["installed_sha256"]) == 64
        if environment["source"] == "lock":
            lock = REPO / environment["file"]
            assert lock.parent.name == "requirements" and "--hash=sha256:" in lock.read_text()
        cpu = session["cpu"]
        assert cpu["torch"] == torch_cpu_capability()
        assert isinstance(cpu["numpy"]["baseline"], list)
        assert isinstance(cpu["numpy"]["dispatch"], list)
    assert sessions_with_other_result_path(tmp_path) == []


def test_sessions_of_other_result_paths_are_listed_with_their_version():
    manifest = {
        "sessions": [
            {"started": "a"},  # before versions were recorded
            {"started": "b", "result_path_version": RESULT_PATH_VERSION},
            {"started": "c", "result_path_version": "0"},
        ]
    }
    assert sessions_with_other_result_path(manifest) == [
        {"index": 0, "started": "a", "result_path_version": None},
        {"index": 2, "started": "c", "result_path_version": "0"},
    ]
    # the committed reference was sampled under this code's version, every session
    assert sessions_with_other_result_path(REPO / "data" / "reference") == []


def test_a_resume_under_other_torch_kernels_is_warned_about(tmp_path):
    config = dataclasses.replace(GOLDEN_CONFIG, runs=1, max_local_searches=1)
    run_experiment(config, tmp_path, progress=False)
    path = manifest_path(tmp_path)
    manifest = read_json(path)
    manifest["sessions"][0]["cpu"]["torch"] = "AVX512"  # as if sampled unpinned elsewhere
    path.write_text(json.dumps(manifest))
    with pytest.warns(CpuKernelWarning, match="AVX512 CPU kernels"):
        run_experiment(dataclasses.replace(config, runs=2), tmp_path, progress=False)


def test_capability_messages_name_both_kernel_sets():
    def manifest(*capabilities):
        return {"sessions": [{"cpu": {"torch": c}} for c in capabilities] + [{}]}

    assert capability_change(manifest("AVX2", "AVX2"), "AVX2") is None
    assert capability_change({"sessions": [{}, {}]}, "AVX512") is None  # none recorded
    message = capability_change(manifest("AVX2"), "AVX512")
    assert "AVX2" in message and "AVX512" in message
    if expected_torch_capability() == "AVX2":
        assert unpinned_message("AVX2") is None
        assert "AVX512" in unpinned_message("AVX512")


@pytest.mark.skipif(
    expected_torch_capability() is None or not CPU_FEATURES.get("AVX2"),
    reason="lonlib pins torch's AVX2 kernels on x86-64 CPUs with AVX2",
)
@pytest.mark.parametrize(
    ("preset", "order", "expected"),
    [
        (None, "import lonlib, torch", "AVX2"),
        (None, "import torch, lonlib", "AVX2"),  # torch reads it at its first kernel
        ("default", "import lonlib, torch", "DEFAULT"),  # a setting of the user's wins
    ],
)
def test_importing_lonlib_pins_torch_to_its_avx2_kernels(preset, order, expected):
    env = {k: v for k, v in os.environ.items() if k != "ATEN_CPU_CAPABILITY"}
    if preset:
        env["ATEN_CPU_CAPABILITY"] = preset
    code = f"{order}; print(torch.backends.cpu.get_cpu_capability())"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.stdout.strip() == expected, out.stderr
