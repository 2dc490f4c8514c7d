"""The one rollout compiled (issue 45): greedy rollouts, verify, a local search, a cold compile.

Every ratio is measured in one run against the numpy definition (``LONLIB_ROLLOUT=numpy``),
on the same machine and load:

* greedy rollout env steps/s at B = 1, 8, 64 Actors (one thread: per core);
* ``lonlib verify data/reference`` wall time, each backend in its own process;
* one DDPG local search at batch 256, one agent, judging every episode: ms per env step;
* the kernels' cold compile (an empty cache folder) and a warm load from the cache.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import best_of, report
from lonlib.config import PendulumConfig
from lonlib.storage import optimum_path, read_experiment_trials, read_optimum
from lonlib.task import compiled
from lonlib.task.rollout import run_actors

ROOT = Path(__file__).resolve().parents[1]
TARGET_ONE_ACTOR = 100_000  # env steps/s per core
TARGET_SEARCH_MS = 1.5  # ms per env step, batch 256, one agent


def reference_actors(root: Path, count: int) -> np.ndarray:
    """``count`` stored Actors of an experiment's accepted optima (repeated when fewer)."""
    trials = read_experiment_trials(root)
    accepted = trials[trials.accepted]
    thetas = [
        read_optimum(optimum_path(root, row.p, int(row.run), int(row.index))).theta
        for row in accepted.itertuples()
    ]
    return np.stack([thetas[i % len(thetas)] for i in range(count)])


def rollout_rate(thetas: np.ndarray, backend: str) -> float:
    """Env steps per second of one greedy rollout of ``thetas [B, P]`` on ``backend``."""
    os.environ[compiled.ROLLOUT_VARIABLE] = backend
    config = PendulumConfig()
    result = run_actors(thetas, config)
    steps = int(result.end_step.sum())
    seconds = best_of(3 if backend == "numba" else 1, lambda: run_actors(thetas, config))
    return steps / seconds


def timed(command: list[str], env: dict[str, str]) -> float:
    """Wall time of a subprocess [s] (it must succeed)."""
    start = time.perf_counter()
    subprocess.run(command, env={**os.environ, **env}, cwd=ROOT, check=True, capture_output=True)
    return time.perf_counter() - start


def printed_number(code: str, backend: str) -> float:
    """The number that ``code`` prints last, run in a process of its own on ``backend``
    (one torch thread)."""
    out = subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, compiled.ROLLOUT_VARIABLE: backend, "OMP_NUM_THREADS": "1"},
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    )
    return float(out.stdout.strip().splitlines()[-1])


def search_ms_per_step(backend: str, steps: int = 6000) -> float:
    """Wall ms per env step of one DDPG local search at batch 256 (one agent, one thread,
    judging every episode), in a process of its own."""
    code = (
        "import time, numpy as np\n"
        "from lonlib.config import DDPGConfig\n"
        "from lonlib.ddpg import local_search\n"
        "from lonlib.config import PendulumConfig\n"
        "from lonlib.task.policy import actor_spec, critic_spec\n"
        "rng = np.random.default_rng(0)\n"
        f"hp = DDPGConfig(batch_size=256, max_steps={steps}, min_steps={steps}, "
        f"patience_steps={steps}, warmup_steps=1000, judge_every=0)\n"
        "env = PendulumConfig()\n"
        "t = time.perf_counter()\n"
        "local_search(actor_spec(2).initial(rng), critic_spec(2).initial(rng), env, hp, seed=0)\n"
        "print(time.perf_counter() - t)\n"
    )
    return 1000 * printed_number(code, backend) / steps


def lockstep_rate(backend: str, k: int = 16, batch: int = 2000) -> float:
    """Agent-steps/s of a reference-like lockstep batch (K slots, batch 2000, judging every
    episode: ``judge_every: 0``) on one torch thread, in a process of its own."""
    code = (
        "from benchmarks.lockstep import agent_steps_per_second\n"
        f"print(agent_steps_per_second({k}, {batch}, 'cpu', 20.0))\n"
    )
    return printed_number(code, backend)


def main() -> None:
    """Run the rollout benchmarks and report them (benchmarks/results/rollout.json)."""
    compiled.kernels()  # compiled (or loaded) before any timing
    compiled.set_threads(1)
    actors = reference_actors(ROOT / "data" / "reference", 64)
    rows = []
    for batch in (1, 8, 64):
        numba_rate = rollout_rate(actors[:batch], "numba")
        numpy_rate = rollout_rate(actors[:batch], "numpy")
        rows.append(
            {
                "measure": f"greedy rollout, {batch} reference Actor(s), env steps/s per core",
                "numba": numba_rate,
                "numpy": numpy_rate,
                "ratio": numba_rate / numpy_rate,
                "target": {1: f">= {TARGET_ONE_ACTOR:,}", 64: ">= 10x"}.get(batch, ""),
            }
        )
    os.environ.pop(compiled.ROLLOUT_VARIABLE, None)
    verify = [sys.executable, "-m", "lonlib.cli", "verify", "data/reference"]
    fast = timed(verify, {compiled.ROLLOUT_VARIABLE: "numba"})
    slow = timed(verify, {compiled.ROLLOUT_VARIABLE: "numpy"})
    rows.append(
        {
            "measure": "lonlib verify data/reference, wall s",
            "numba": fast,
            "numpy": slow,
            "ratio": slow / fast,
            "target": "<= 1/5 of numpy",
        }
    )
    numba_ms, numpy_ms = search_ms_per_step("numba"), search_ms_per_step("numpy")
    rows.append(
        {
            "measure": "DDPG local search, batch 256, 1 agent, judge every episode, ms/env step",
            "numba": numba_ms,
            "numpy": numpy_ms,
            "ratio": numpy_ms / numba_ms,
            "target": f"<= {TARGET_SEARCH_MS} ms",
        }
    )
    fast, slow = lockstep_rate("numba"), lockstep_rate("numpy")
    rows.append(
        {
            "measure": "lockstep K = 16, batch 2000, judge_every 0, agent-steps/s per core",
            "numba": fast,
            "numpy": slow,
            "ratio": fast / slow,
            "target": ">= 1.5x",
        }
    )
    load = [sys.executable, "-c", "from lonlib.task import compiled; compiled.kernels()"]
    with tempfile.TemporaryDirectory() as cache:
        cold = timed(load, {compiled.CACHE_VARIABLE: cache, compiled.ROLLOUT_VARIABLE: "numba"})
        warm = timed(load, {compiled.CACHE_VARIABLE: cache, compiled.ROLLOUT_VARIABLE: "numba"})
    rows.append({"measure": "kernels: cold compile (empty cache), process wall s", "numba": cold})
    rows.append({"measure": "kernels: load from the cache, process wall s", "numba": warm})
    rows.append({"measure": "load average (1 min) at the end", "numba": os.getloadavg()[0]})
    report("rollout", rows)


if __name__ == "__main__":
    main()
