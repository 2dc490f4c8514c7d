"""Gymnasium lockstep speed: agent-steps per second of ``K`` local searches of lonlib's DDPG
on Gymnasium's ``Pendulum-v1`` trained as one
:class:`lonlib.ddpg.gymnasium_search.GymnasiumSlotTrainer` (the training environments one
``SyncVectorEnv``, one batched update), past the warm-up, at the worked example's batch of
256 (``configs/pendulum-v1.yaml``). K = 1 is the serial executor's search. ``BENCH_GYM_KS``
overrides the K values (comma separated).
"""

from __future__ import annotations

import os
import time

import numpy as np

from benchmarks.common import report
from lonlib.config import DDPGConfig, GymnasiumTaskConfig
from lonlib.ddpg.gymnasium_search import GymnasiumSlotTrainer
from lonlib.task import GymnasiumTask

KS = tuple(int(k) for k in os.environ.get("BENCH_GYM_KS", "1,4,16").split(","))
WARMUP = 300


def agent_steps_per_second(k: int, batch: int = 256, seconds: float = 6.0) -> float:
    """Agent-steps per second of ``k`` slots past their warm-up (timed for ~``seconds``)."""
    task = GymnasiumTask(GymnasiumTaskConfig("Pendulum-v1", (-3254.72, 0.0)))
    hp = DDPGConfig(
        batch_size=batch,
        buffer_size=50_000,
        warmup_steps=WARMUP,
        max_steps=10**9,
        min_steps=10**9,
        patience_steps=10**9,
    )
    rng = np.random.default_rng(0)
    thetas = np.stack([task.actor_spec.initial(rng) for _ in range(k)])
    omegas = np.stack([task.critic_spec.initial(rng) for _ in range(k)])
    trainer = GymnasiumSlotTrainer(task, thetas, omegas, list(range(k)), hp)
    for _ in range(WARMUP + 10):
        trainer.step()
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds or steps < 5:
        trainer.step()
        steps += 1
    return k * steps / (time.perf_counter() - start)


def main() -> None:
    """Print and store the K-scaling table."""
    base = None
    rows = []
    for k in KS:
        rate = agent_steps_per_second(k)
        base = rate if base is None else base
        rows.append({"K": k, "agent_steps/s": rate, "vs_K=1": rate / base})
    report("gymnasium_lockstep_scaling", rows)


if __name__ == "__main__":
    main()
