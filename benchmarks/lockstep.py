"""Lockstep speed: agent-steps per second of K local searches trained as one batch, the
quick experiment through the lockstep and pool executors, and projected paper-scale times.

K-scaling runs a :class:`lonlib.ddpg.trainer.SlotTrainer` of the paper's networks on two carts
(buffer 40 000, paper DDPG settings) past its warm-up and times whole steps: actions,
environments, replay writes and samples, one batched update and the greedy evaluations of
the episodes that end. It runs on the CPU (one torch thread) and, when torch sees one, on
CUDA. ``BENCH_LOCKSTEP_KS`` overrides the K values (comma separated).
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from benchmarks.common import RESULTS, report
from lonlib.config import DDPGConfig, PendulumConfig, named_config
from lonlib.ddpg.trainer import SlotTrainer
from lonlib.experiment.running import run_experiment
from lonlib.storage.trials import read_experiment_trials
from lonlib.task.policy import actor_spec, critic_spec

ENV = PendulumConfig(n_carts=2)
KS = tuple(int(k) for k in os.environ.get("BENCH_LOCKSTEP_KS", "1,4,16,64,256").split(","))
WARMUP = 300
# The paper's experiment: 2 p x 100 runs, each T + 1 = 6 to ~10 local searches of 60k (the
# patience floor min_steps) to 150k (the budget) env steps.
PAPER_AGENT_STEPS = {"low": 200 * 6 * 60_000, "high": 200 * 10 * 150_000}
CLUSTER_CORES = 64


def agent_steps_per_second(k: int, batch: int, device: str, seconds: float = 6.0) -> float:
    """Agent-steps per second of ``k`` slots past their warm-up (timed for ~``seconds``)."""
    hp = DDPGConfig(
        batch_size=batch,
        warmup_steps=WARMUP,
        max_steps=10**9,
        min_steps=10**9,
        patience_steps=10**9,
        device=device,
    )
    rng = np.random.default_rng(0)
    thetas = np.stack([actor_spec(2).initial(rng) for _ in range(k)])
    omegas = np.stack([critic_spec(2).initial(rng) for _ in range(k)])
    trainer = SlotTrainer(thetas, omegas, list(range(k)), ENV, hp)
    for _ in range(WARMUP + 20):
        trainer.step()
    sync = torch.cuda.synchronize if device == "cuda" else (lambda: None)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds or steps < 5:
        trainer.step()
        steps += 1
    sync()
    return k * steps / (time.perf_counter() - start)


def scaling_rows() -> list[dict]:
    """Agent-steps per second against K, batch 256 and 2000, CPU and (if present) CUDA."""
    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    rows = []
    for device in devices:
        for batch in (256, 2000):
            base = None
            for k in KS:
                rate = agent_steps_per_second(k, batch, device)
                base = base or rate
                rows.append(
                    {
                        "device": device,
                        "batch": batch,
                        "K": k,
                        "agent-steps/s": rate,
                        "ms per agent-step": 1e3 / rate,
                        "vs K=1": rate / base,
                    }
                )
    return rows


def executor_rows(workers: int = 2, slots: int = 8) -> list[dict]:
    """The quick configuration's local searches (one per run, a fixed 8000-step budget so
    every executor does the same work) through the pool executor with ``workers``
    processes, lockstep with ``slots`` slots in one process, and lockstep in ``workers``
    processes: env steps per second (issue 17's target: lockstep >= 3x the pool)."""
    quick = named_config("quick")
    ddpg = dataclasses.replace(quick.ddpg, max_steps=8000, min_steps=8000, patience_steps=8000)
    config = dataclasses.replace(quick, max_local_searches=1, ddpg=ddpg)
    rows = []
    for name, options in (
        (f"pool, {workers} processes", {"executor": "pool", "workers": workers}),
        (f"lockstep, 1 process x {slots} slots", {"executor": "lockstep", "slots": slots}),
        (
            f"lockstep, {workers} processes x {slots // workers} slots",
            {"executor": "lockstep", "slots": slots // workers, "workers": workers},
        ),
    ):
        with tempfile.TemporaryDirectory() as folder:
            start = time.perf_counter()
            run_experiment(config, Path(folder), progress=False, **options)
            seconds = time.perf_counter() - start
            steps = int(read_experiment_trials(Path(folder))["env_steps"].sum())
        rows.append(
            {
                "executor": name,
                "env steps": steps,
                "seconds": seconds,
                "env steps/s": steps / seconds,
            }
        )
    for row in rows:
        row["vs pool"] = row["env steps/s"] / rows[0]["env steps/s"]
    return rows


def projection_rows(scaling: list[dict]) -> list[dict]:
    """Projected wall time of CONFIG=paper (batch 2000) from the measured rates: this
    machine's cores as a pool (K = 1 per core), a 64-core Dask cluster, and lockstep on
    this machine's CPU and on each GPU measured."""
    at = {(r["device"], r["batch"], r["K"]): r["agent-steps/s"] for r in scaling}
    single = at.get(("cpu", 2000, 1))
    cores = os.cpu_count() or 1
    options = []
    if single:
        options.append((f"this machine, pool of {cores} processes (K = 1 each)", single * cores))
        options.append(
            (f"Dask cluster of {CLUSTER_CORES} cores (K = 1 each)", single * CLUSTER_CORES)
        )
    for device in ("cpu", "cuda"):
        rates = {k: rate for (d, b, k), rate in at.items() if d == device and b == 2000}
        if rates:
            k = max(rates, key=rates.get)
            where = "this machine's CPU" if device == "cpu" else torch.cuda.get_device_name()
            options.append((f"lockstep on {where}, K = {k}", rates[k]))
    return [
        {
            "paper scale on": name,
            "agent-steps/s": rate,
            "hours (low)": PAPER_AGENT_STEPS["low"] / rate / 3600,
            "hours (high)": PAPER_AGENT_STEPS["high"] / rate / 3600,
        }
        for name, rate in options
    ]


def markdown(scaling: list[dict], executors: list[dict], projection: list[dict]) -> str:
    """The lockstep tables of docs/performance.md (``benchmarks/results/lockstep.md``)."""
    lines = ["| device | batch | " + " | ".join(f"K = {k}" for k in KS) + " |"]
    lines.append("|---|---|" + "---|" * len(KS))
    for device in dict.fromkeys(r["device"] for r in scaling):
        for batch in (256, 2000):
            rates = [
                r["agent-steps/s"] for r in scaling if r["device"] == device and r["batch"] == batch
            ]
            lines.append(f"| {device} | {batch} | " + " | ".join(f"{v:,.0f}" for v in rates) + " |")
    lines.append(
        "\nAgent-steps per second (env, actions, replay, batched update, greedy evaluations).\n"
    )
    lines.append("| quick's searches (8 runs x 8000 steps) through | env steps/s | vs the pool |")
    lines.append("|---|---|---|")
    for row in executors:
        lines.append(f"| {row['executor']} | {row['env steps/s']:,.0f} | {row['vs pool']:.2g}x |")
    lines.append(
        "\n| CONFIG=paper (72M-300M agent-steps) on | agent-steps/s | projected wall time |"
    )
    lines.append("|---|---|---|")
    for row in projection:
        lines.append(
            f"| {row['paper scale on']} | {row['agent-steps/s']:,.0f} "
            f"| {row['hours (low)']:.3g}-{row['hours (high)']:.3g} h |"
        )
    load = os.getloadavg()[0]
    lines.append(f"\nMeasured with load average {load:.1f} on {os.cpu_count()} cores.")
    return "\n".join(lines) + "\n"


def main() -> None:
    """Run the lockstep benchmarks, print them, write results/lockstep.json and .md."""
    torch.set_num_threads(1)
    scaling = scaling_rows()
    report("lockstep_scaling", scaling)
    executors = executor_rows()
    report("lockstep_executors", executors)
    projection = projection_rows(scaling)
    report("lockstep_projection", projection)
    table = markdown(scaling, executors, projection)
    (RESULTS / "lockstep.md").write_text(table)
    print(f"\n{table}")


if __name__ == "__main__":
    main()
