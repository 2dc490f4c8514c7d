"""Shared fixtures: a tiny experiment whose local searches take a fraction of a second."""

import fcntl
import os
import pickle
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

import lonlib  # noqa: F401  (first: it pins torch's CPU kernels before any test uses torch)
from lonlib.config import DDPGConfig

# One cart, 40-step episodes, a "swing high" fitness (upright within 2.9 rad of the top),
# and a DDPG budget of 150 steps: fitness values vary, so LONs are not trivial.
TINY = """
name: tiny
perturbations: [1.0e-3, 1.0e-4]
runs: 2
tolerance: 2
max_local_searches: 4
env: {n_carts: 1, steps: 40, upright_angle: 2.9, motor: acceleration, motor_gain: 2.0}
ddpg: {batch_size: 32, buffer_size: 500, warmup_steps: 50, max_steps: MAX, min_steps: 0,
       patience_steps: 1000}
"""


# The DDPG settings of the tests' small, fast local searches (the tiny experiment's above too):
# batches of 32 from a replay of 500 transitions, 50 warm-up steps, no minimum length.
TINY_DDPG = {"batch_size": 32, "buffer_size": 500, "warmup_steps": 50, "min_steps": 0}


def tiny_ddpg(**overrides) -> DDPGConfig:
    """A :class:`DDPGConfig` of :data:`TINY_DDPG`'s settings, then ``overrides``
    (``tiny_ddpg(max_steps=120, patience_steps=10**6)``)."""
    return DDPGConfig(**{**TINY_DDPG, **overrides})


def write_tiny_yaml(folder: Path, max_steps: int = 150) -> Path:
    """Write the tiny experiment's YAML into ``folder`` and return its path."""
    path = folder / "tiny.yaml"
    path.write_text(TINY.replace("MAX", str(max_steps)))
    return path


def built_once(tmp_path_factory, name: str, build: Callable[[Path], None]) -> Path:
    """The folder ``build(folder)`` fills, built once per test session: the first of the
    pytest-xdist workers to ask builds it (the others wait for it), later calls find it.
    Treat it as read-only (copy it to change it): every worker reads the same folder."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's folder, above each worker's own
    folder, done = root / f"built-once-{name}", root / f"built-once-{name}.done"
    with open(root / f"built-once-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            shutil.rmtree(folder, ignore_errors=True)  # a build that failed part-way
            folder.mkdir()
            build(folder)
            done.touch()
    return folder


def _run_tiny(folder: Path) -> None:
    from lonlib.config import load_config
    from lonlib.experiment.running import run_experiment

    config = load_config(write_tiny_yaml(folder))
    trials = run_experiment(config, folder / "out", progress=False)
    (folder / "trials.pickle").write_bytes(pickle.dumps(trials))


@pytest.fixture(scope="session")
def tiny_experiment(tmp_path_factory):
    """A finished tiny experiment: (config, folder, trials). Run once per session (see
    :func:`built_once`); each worker gets its own copy of the folder, and the trials that
    run returned."""
    from lonlib.config import load_config

    shared = built_once(tmp_path_factory, "tiny", _run_tiny)
    folder = tmp_path_factory.mktemp("tiny")
    shutil.copytree(shared, folder, dirs_exist_ok=True)
    trials = pickle.loads((folder / "trials.pickle").read_bytes())
    return load_config(folder / "tiny.yaml"), folder / "out", trials


@pytest.fixture(params=["cpu", "cpu as device"])
def device_mode(request):
    """Each test twice: on the CPU as it is, and with the CPU taking every path a CUDA
    device takes (:func:`lonlib.ddpg.devices.cpu_as_device`, for objects made in the test)."""
    from lonlib.ddpg.devices import cpu_as_device

    if request.param == "cpu":
        yield request.param
    else:
        with cpu_as_device():
            yield request.param


def reseal(folder: Path) -> Path:
    """Seal an experiment folder a test crafted by hand (runs truncated, a version stamped,
    a recording planted) as if lonlib had written it so: the old seal removed, the runs,
    the recordings and the figures sealed as they are now (:mod:`lonlib.storage.digests`)."""
    from lonlib.analysis.recordings import recordings_index
    from lonlib.storage.digests import (
        RUN_DIGESTS,
        SEAL_NAME,
        figure_files,
        reseal_outputs,
        seal_runs,
    )
    from lonlib.storage.layout import read_manifest

    folder = Path(folder)
    (folder / SEAL_NAME).unlink(missing_ok=True)
    for path in folder.glob(f"p=*/run_*/{RUN_DIGESTS}"):
        path.unlink()
    seal_runs(folder, read_manifest(folder))
    figures = figure_files(folder)
    reseal_outputs(folder, figures=figures, recordings=recordings_index(folder))
    return folder


def sample_small(folder: Path, p: float, searches: int, name: str) -> tuple[object, Path, Path]:
    """The tiny experiment at one ``p``, two runs of ``searches`` 60-step local searches,
    its YAML written as ``folder/<name>.yaml`` and sampled uninterrupted into ``folder/out``:
    (config, YAML path, output folder)."""
    import dataclasses

    import yaml

    from lonlib.config import load_config
    from lonlib.experiment.running import run_experiment

    tiny = load_config(write_tiny_yaml(folder, max_steps=60))
    config = dataclasses.replace(tiny, perturbations=(p,), max_local_searches=searches)
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(config.to_dict()))
    run_experiment(config, folder / "out", progress=False)
    return config, path, folder / "out"
