"""DDPG throughput: batched updates per agent for k agents, and lonlib versus SB3.

Both sides use one torch thread, the paper's networks (sigmoid MLPs 20-20-20), batch 2000,
buffer 40 000, lr 1e-3, gamma 0.99, tau 0.005, N(0, 0.1) action noise and one gradient step
per environment step on the two-cart task.
"""

from __future__ import annotations

import copy
import time

import numpy as np
import torch

from benchmarks.common import report
from lonlib.ddpg import DDPGConfig, ReplayBuffer, _update, local_search
from lonlib.nets import BatchedMLP, actor_spec, critic_spec
from lonlib.pendulum import PendulumConfig

HP = DDPGConfig(warmup_steps=2000, min_steps=0, patience_steps=10**9)
ENV = PendulumConfig(n_carts=2)


def updates_per_second_per_agent(k: int, updates: int = 20, threads: int = 1) -> float:
    """Batched DDPG updates of ``k`` agents on a full replay buffer of random transitions."""
    torch.set_num_threads(threads)
    rng = np.random.default_rng(0)
    a_spec, c_spec = actor_spec(2), critic_spec(2)
    actor = BatchedMLP(a_spec, np.stack([a_spec.initial(rng) for _ in range(k)]))
    critic = BatchedMLP(c_spec, np.stack([c_spec.initial(rng) for _ in range(k)]))
    targets = copy.deepcopy(actor), copy.deepcopy(critic)
    optims = [torch.optim.Adam(m.parameters(), lr=1e-3, fused=True) for m in (actor, critic)]
    replay = ReplayBuffer(k, HP.buffer_size, 20, 2, torch.device("cpu"))
    replay.data.uniform_()
    replay.data[..., -1] = 1.0  # no terminal transitions
    replay.size = HP.buffer_size

    def one() -> None:
        idx = np.stack([rng.integers(0, replay.size, HP.batch_size) for _ in range(k)])
        _update(replay.sample(idx), actor, critic, *targets, optims[0], optims[1], HP)

    for _ in range(3):
        one()
    start = time.perf_counter()
    for _ in range(updates):
        one()
    return updates * k / (time.perf_counter() - start)


def lonlib_seconds_per_2000_training_steps() -> float:
    """Wall time of 2000 environment steps with training in lonlib's local search (k = 1)."""
    rng = np.random.default_rng(0)
    theta, omega = actor_spec(2).initial(rng), critic_spec(2).initial(rng)

    def run(steps: int) -> float:
        hp = DDPGConfig(**{**HP.__dict__, "max_steps": steps})
        start = time.perf_counter()
        local_search(theta, omega, ENV, hp, seed=0)
        return time.perf_counter() - start

    return run(4000) - run(2000)


def sb3_seconds_per_2000_training_steps(threads: int = 1) -> float | None:
    """The same for Stable-Baselines3's DDPG on the Gymnasium env (None if not installed)."""
    try:
        import gymnasium as gym
        from stable_baselines3 import DDPG
        from stable_baselines3.common.noise import NormalActionNoise
    except ImportError:
        return None
    import lonlib  # noqa: F401  (registers the env)

    torch.set_num_threads(threads)

    def run(steps: int) -> float:
        env = gym.make(lonlib.ENV_ID, n_carts=2)
        model = DDPG(
            "MlpPolicy",
            env,
            buffer_size=HP.buffer_size,
            batch_size=HP.batch_size,
            learning_rate=HP.learning_rate,
            gamma=HP.gamma,
            tau=HP.tau,
            train_freq=1,
            gradient_steps=1,
            learning_starts=HP.warmup_steps,
            action_noise=NormalActionNoise(np.zeros(2), np.full(2, HP.noise_std)),
            policy_kwargs={"net_arch": [20, 20, 20], "activation_fn": torch.nn.Sigmoid},
            device="cpu",
            seed=0,
        )
        start = time.perf_counter()
        model.learn(total_timesteps=steps)
        return time.perf_counter() - start

    return run(4000) - run(2000)


def main() -> None:
    """Run the DDPG benchmarks and report them (one and two torch threads on both sides)."""
    rows = []
    ours = lonlib_seconds_per_2000_training_steps()
    for threads in (1, 2):
        sb3 = sb3_seconds_per_2000_training_steps(threads)
        sb3_rate = 2000 / sb3 if sb3 else None
        for k in (1, 16, 64):
            rate = updates_per_second_per_agent(k, threads=threads)
            rows.append(
                {
                    "measure": f"updates/s per agent, k = {k}",
                    "threads": threads,
                    "value": rate,
                    "x SB3 steps/s": rate / sb3_rate if sb3 else None,
                }
            )
        if sb3:
            rows.append(
                {
                    "measure": "SB3 DDPG: s per 2000 training env-steps",
                    "threads": threads,
                    "value": sb3,
                }
            )
        else:
            rows.append({"measure": "SB3 not installed (pip install -e .[bench])", "value": None})
    torch.set_num_threads(1)
    rows.append(
        {"measure": "lonlib: s per 2000 training env-steps (k = 1)", "threads": 1, "value": ours}
    )
    sb3_one = next((r["value"] for r in rows if r["measure"].startswith("SB3 DDPG")), None)
    if sb3_one:
        rows.append(
            {"measure": "SB3 time / lonlib time (k = 1)", "threads": 1, "value": sb3_one / ours}
        )
    report("ddpg", rows)
