"""Simulator throughput and the cost of one Algorithm 1 fitness evaluation."""

from __future__ import annotations

import numpy as np

from benchmarks.common import best_of, report
from lonlib.config import PendulumConfig
from lonlib.task.pendulum import CoupledPendulums
from lonlib.task.policy import actor_spec, forward_numpy
from lonlib.task.rollout import evaluate

PROTOTYPE_STEPS_PER_SECOND = 1.5e6  # plain numpy prototype, two carts, B = 2000, one core


def steps_per_second(batch: int, n_carts: int = 2, steps: int = 200, observe: bool = True) -> float:
    """Environment-steps per second of the batched simulator (optionally with sensors)."""
    cfg = PendulumConfig(n_carts=n_carts, steps=3000)
    sim = CoupledPendulums(cfg, batch)
    actions = np.full((batch, n_carts), 0.5)

    def run() -> None:
        sim.reset()
        for _ in range(steps):
            if observe:
                sim.observe()
            sim.step(actions)

    return batch * steps / best_of(3, run)


def fitness_evaluation_seconds(n_carts: int = 2) -> tuple[float, int]:
    """Wall time of one full 2000-step evaluation of a paper-sized Actor in numpy."""
    cfg = PendulumConfig(n_carts=n_carts)
    spec = actor_spec(n_carts)
    theta = spec.initial(np.random.default_rng(0)).astype(np.float64)
    # Zero the output layer so the policy never pushes and the episode runs all 2000 steps.
    weight, bias = spec.unflatten(theta)[-1]
    weight[:] = 0.0
    bias[:] = 0.0
    result = evaluate(lambda obs: forward_numpy(spec, theta, obs), cfg)
    seconds = best_of(3, lambda: evaluate(lambda obs: forward_numpy(spec, theta, obs), cfg))
    return seconds, int(result.steps[0])


def main() -> None:
    """Run the simulator benchmarks and report them."""
    rows = []
    for batch in (1, 1024, 2000):
        for observe in (False, True):
            sps = steps_per_second(batch, observe=observe)
            rows.append(
                {
                    "measure": "env-steps/s (2 carts)" + (" + sensors" if observe else ""),
                    "batch": batch,
                    "value": sps,
                    "vs prototype 1.5M/s": sps / PROTOTYPE_STEPS_PER_SECOND
                    if batch == 2000
                    else None,
                }
            )
    seconds, steps = fitness_evaluation_seconds()
    rows.append(
        {
            "measure": f"one {steps}-step fitness evaluation, numpy Actor [s]",
            "batch": 1,
            "value": seconds,
        }
    )
    report("simulator", rows)
