"""DDPG speed: one update (lean versus autograd) beside its targets, k agents batched, and
lonlib's local search versus Stable-Baselines3's DDPG.

Everything runs on one torch thread with the paper's networks (sigmoid MLPs 20-20-20, two
carts), buffer 40 000, lr 1e-3, gamma 0.99, tau 0.005 and N(0, 0.1) action noise. The
machine is shared, so every figure is the median of several runs, lean and autograd runs
alternate, and the load average is reported beside them.
"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable

import numpy as np
import torch

from benchmarks.common import RESULTS, report
from lonlib.config import DDPGConfig, PendulumConfig
from lonlib.ddpg.learner import learner_class
from lonlib.ddpg.replay import ReplayBuffer
from lonlib.ddpg.search import local_search
from lonlib.task.policy import actor_spec, critic_spec

HP = DDPGConfig(warmup_steps=2000, min_steps=0, patience_steps=10**9)
ENV = PendulumConfig(n_carts=2)
TARGET_MS = {2000: 1.2, 256: 0.3}  # issue 12: one update, k = 1, one thread
REPEATS = int(os.environ.get("BENCH_REPEATS", "5"))
TRAINING_REPEATS = max(1, (REPEATS + 1) // 2)
LEAN_TRAINING, AUTOGRAD_TRAINING = "lonlib, lean update", "lonlib, autograd update"
LEAN_256 = "lonlib, lean update, batch 256"
SEARCH_TARGET_S = 45.0  # issue 12: a 150 000-step local search at batch 256, per agent
SB3_TARGET = 3.0  # issue 12: SB3's DDPG at least this many times slower per agent-step
SB3_TRAINING = "Stable-Baselines3 DDPG"


def make_update(kind: str, k: int, batch: int) -> Callable[[], object]:
    """One DDPG update of ``k`` agents (``kind`` ``"lean"`` or ``"autograd"``) on a batch
    sampled from a full replay buffer of random transitions (a tenth of them terminal)."""
    rng = np.random.default_rng(0)
    a_spec, c_spec = actor_spec(2), critic_spec(2)
    learner = learner_class(kind)(
        a_spec,
        c_spec,
        np.stack([a_spec.initial(rng) for _ in range(k)]),
        np.stack([c_spec.initial(rng) for _ in range(k)]),
        learning_rate=HP.learning_rate,
        gamma=HP.gamma,
        tau=HP.tau,
    )
    replay = ReplayBuffer(k, HP.buffer_size, 20, 2, torch.device("cpu"))
    replay.data.uniform_()
    replay.data[..., -1] = (replay.data[..., -1] > 0.1).float()
    replay.size[:] = HP.buffer_size
    sample = replay.sample(rng.integers(0, HP.buffer_size, (k, batch)))
    return lambda: learner.update(sample)


def update_ms(k: int, batch: int, updates: int = 40) -> dict[str, tuple[list[float], float]]:
    """Per learner: milliseconds per update, one mean per run of ``updates`` updates, and the
    fastest single update (the least disturbed by other processes); lean and autograd runs
    alternate so both see the same load."""
    work = {kind: make_update(kind, k, batch) for kind in ("lean", "autograd")}
    means: dict[str, list[float]] = {kind: [] for kind in work}
    fastest = dict.fromkeys(work, float("inf"))
    for one in work.values():
        for _ in range(5):
            one()
    for _ in range(REPEATS):
        for kind, one in work.items():
            total = 0.0
            for _ in range(updates):
                start = time.perf_counter()
                one()
                seconds = time.perf_counter() - start
                total += seconds
                fastest[kind] = min(fastest[kind], seconds * 1e3)
            means[kind].append(total / updates * 1e3)
    return {kind: (means[kind], fastest[kind]) for kind in work}


def lonlib_seconds_per_2000_training_steps(update: str, batch: int = 2000) -> float:
    """Wall time of 2000 environment steps with training in lonlib's local search (k = 1)."""
    rng = np.random.default_rng(0)
    theta, omega = actor_spec(2).initial(rng), critic_spec(2).initial(rng)

    def run(steps: int) -> float:
        hp = DDPGConfig(
            **{**HP.__dict__, "max_steps": steps, "update": update, "batch_size": batch}
        )
        start = time.perf_counter()
        local_search(theta, omega, ENV, hp, seed=0)
        return time.perf_counter() - start

    return run(4000) - run(2000)


def sb3_seconds_per_2000_training_steps() -> float | None:
    """The same for Stable-Baselines3's DDPG on the Gymnasium env (None if not installed)."""
    try:
        import gymnasium as gym
        from stable_baselines3 import DDPG
        from stable_baselines3.common.noise import NormalActionNoise
    except ImportError:
        return None
    import lonlib  # noqa: F401  (registers the env)

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


def update_rows() -> list[dict]:
    """One row per (batch, k): lean and autograd medians and fastest single updates, the
    spread of the lean runs, the speed-up and the target."""
    rows = []
    for batch in (2000, 256):
        for k in (1, 3, 16):
            (lean_runs, lean_min), (reference_runs, reference_min) = update_ms(k, batch).values()
            lean, reference = statistics.median(lean_runs), statistics.median(reference_runs)
            rows.append(
                {
                    "batch": batch,
                    "k": k,
                    "lean ms": lean,
                    "lean runs": f"{min(lean_runs):.3g}-{max(lean_runs):.3g}",
                    "lean min": lean_min,
                    "autograd ms": reference,
                    "autograd min": reference_min,
                    "speed-up": reference / lean,
                    "lean ms per agent": lean / k,
                    "target ms": TARGET_MS[batch] if k == 1 else None,
                    "met": ("yes" if lean <= TARGET_MS[batch] else "no") if k == 1 else None,
                }
            )
    return rows


def training_rows() -> list[dict]:
    """Seconds per 2000 training env-steps (k = 1, batch 2000): lonlib lean, autograd, SB3,
    measured in turn within each repeat so all three see the same load."""
    measures = {
        LEAN_TRAINING: lambda: lonlib_seconds_per_2000_training_steps("lean"),
        LEAN_256: lambda: lonlib_seconds_per_2000_training_steps("lean", 256),
        AUTOGRAD_TRAINING: lambda: lonlib_seconds_per_2000_training_steps("autograd"),
        SB3_TRAINING: sb3_seconds_per_2000_training_steps,
    }
    values: dict[str, list] = {name: [] for name in measures}
    for _ in range(TRAINING_REPEATS):
        for name, measure in measures.items():
            values[name].append(measure())
    rows, sb3 = [], None
    for name, seconds in values.items():
        if None in seconds:
            rows.append({"training": f"{name}: not installed (pip install -e .[bench])"})
            continue
        rows.append({"training": name, "s per 2000 steps": statistics.median(seconds)})
        sb3 = rows[-1]["s per 2000 steps"] if name == SB3_TRAINING else sb3
    for row in rows:
        if sb3 and "s per 2000 steps" in row:
            row["SB3 time / this"] = sb3 / row["s per 2000 steps"]
    return rows


def markdown(update: list[dict], training: list[dict], load: tuple[float, float]) -> str:
    """The DDPG speed table of docs/performance.md (``benchmarks/results/ddpg.md``)."""
    lines = [
        "| DDPG, one torch thread | lean: median (fastest) | autograd: median (fastest) "
        "| lean speed-up | target (k = 1, median) |",
        "|---|---|---|---|---|",
    ]
    for row in update:
        target = f"<= {row['target ms']} ms: {row['met']}" if row["target ms"] else ""
        k = row["k"]
        per_agent = f" ({row['lean ms per agent']:.3g} ms per agent)" if k > 1 else ""
        lines.append(
            f"| one update, batch {row['batch']}, k = {k} | {row['lean ms']:.3g} "
            f"({row['lean min']:.3g}) ms{per_agent} | {row['autograd ms']:.3g} "
            f"({row['autograd min']:.3g}) ms | {row['speed-up']:.2g}x | {target} |"
        )
    seconds = {
        row["training"]: row["s per 2000 steps"] for row in training if "s per 2000 steps" in row
    }
    if LEAN_256 in seconds:
        search = seconds[LEAN_256] * 75
        met = "yes" if search <= SEARCH_TARGET_S else "no"
        lines.append(
            f"| a 150 000-step local search, batch 256, k = 1 (75 x 2000 training steps) "
            f"| {search:.3g} s | | | <= {SEARCH_TARGET_S:g} s: {met} |"
        )
    lean, reference = seconds.get(LEAN_TRAINING), seconds.get(AUTOGRAD_TRAINING)
    sb3 = seconds.get(SB3_TRAINING)
    if lean and reference:
        met = "yes" if sb3 and sb3 / lean >= SB3_TARGET else "no"
        versus = (
            f"; SB3 {sb3:.3g} s, {sb3 / lean:.2g}x the lean time (target >= {SB3_TARGET:g}x: {met})"
            if sb3
            else ""
        )
        lines.append(
            f"| 2000 training env-steps (k = 1, batch 2000) | {lean:.3g} s | {reference:.3g} s "
            f"| {reference / lean:.2g}x{versus} | |"
        )
    lines.append(
        f"\nMedians of {REPEATS} runs (training: {TRAINING_REPEATS}); load average "
        f"{load[0]:.1f} before, {load[1]:.1f} after, on {os.cpu_count()} cores."
    )
    return "\n".join(lines) + "\n"


def main() -> None:
    """Run the DDPG benchmarks, print them and write results/ddpg.json and results/ddpg.md."""
    torch.set_num_threads(1)
    before = os.getloadavg()[0]
    update = update_rows()
    report("ddpg_update", update)
    training = training_rows()
    report("ddpg_training", training)
    after = os.getloadavg()[0]
    print(f"load average (1 min): {before:.1f} before, {after:.1f} after")
    table = markdown(update, training, (before, after))
    (RESULTS / "ddpg.md").write_text(table)
    print(f"\n{table}")
