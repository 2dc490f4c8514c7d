"""Shared fixtures: a tiny experiment whose local searches take a fraction of a second."""

from pathlib import Path

import pytest

import lonlib  # noqa: F401  (first: it pins torch's CPU kernels before any test uses torch)

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


def write_tiny_yaml(folder: Path, max_steps: int = 150) -> Path:
    """Write the tiny experiment's YAML into ``folder`` and return its path."""
    path = folder / "tiny.yaml"
    path.write_text(TINY.replace("MAX", str(max_steps)))
    return path


@pytest.fixture(scope="session")
def tiny_experiment(tmp_path_factory):
    """A finished tiny experiment: (config, folder, trials)."""
    from lonlib.experiment.running import load_config, run_experiment

    folder = tmp_path_factory.mktemp("tiny")
    config = load_config(write_tiny_yaml(folder))
    trials = run_experiment(config, folder / "out", progress=False)
    return config, folder / "out", trials


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
