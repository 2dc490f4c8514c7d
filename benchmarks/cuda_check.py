"""The lockstep executor on a CUDA device (issue 30, item 3), in one short script.

Run on a machine with a GPU (``python -m benchmarks.cuda_check OUT``); every section writes
its rows to ``OUT/cuda_check.json`` as soon as it finishes (a section that fails records its
error and the next one runs), and the whole script keeps to a time budget
(``CUDA_CHECK_SECONDS``, default 330 s). Sections:

1. **updates**: CPU and CUDA learners from the same parameters, fed the same batches, one
   update at a time: the largest parameter difference after N updates (absolute, and
   relative to the parameters' largest magnitude). Whole trials cannot agree (the task is
   chaotic); single updates can, to rounding.
2. **K**: does a search's result on CUDA depend on how many slots train beside it? One
   search alone (K = 1) against the same search in slot 0 of K = 4 and K = 16, the Actor
   compared after a fixed number of steps, bit for bit and in size.
3. **rates**: lockstep agent-steps per second, K in {1, 16, 64, 256} x batch {256, 2000},
   over one whole training episode past the warm-up (so every slot's episode ends once and
   its greedy evaluation is timed): the share of the wall time spent in the host-side greedy
   rollouts (``SlotTrainer._judge_pending``).
4. **profile**: one step at K = 200, batch 2000 under torch's profiler: the kernels by CUDA
   time, host-to-device and device-to-host copies, launches.
5. **paper**: ``CONFIG=paper`` (2 x 100 runs, K = 200 in one batch) projected from section 3.

With no GPU it runs every section on the CPU in small sizes (``--smoke``), to check the script.
``CUDA_CHECK_SECTIONS`` (comma-separated names) runs some sections only; the rate rows'
slot counts, batch sizes and ``ddpg.judge_every`` come from ``CUDA_CHECK_KS``,
``CUDA_CHECK_BATCHES`` and ``CUDA_CHECK_JUDGE_EVERY``.
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
import sys
import time
import traceback
from pathlib import Path

import numpy as np
import torch

from lonlib.config import DDPGConfig, PendulumConfig
from lonlib.ddpg.learner import make_learner
from lonlib.ddpg.trainer import SlotTrainer
from lonlib.task.policy import actor_spec, critic_spec

ENV = PendulumConfig(n_carts=2)
A_SPEC, C_SPEC = actor_spec(2), critic_spec(2)
BUDGET = float(os.environ.get("CUDA_CHECK_SECONDS", "330"))
# CONFIG=paper: 2 p x 100 runs, each T + 1 = 6 to ~10 local searches of 60k (the patience
# floor) to 150k (the budget) env steps (benchmarks/lockstep.py).
PAPER_AGENT_STEPS = {"low": 200 * 6 * 60_000, "high": 200 * 10 * 150_000}
T0 = time.perf_counter()
JUDGE_EVERY = int(os.environ.get("CUDA_CHECK_JUDGE_EVERY", "0"))
"""``ddpg.judge_every`` of the rate rows' trainers (0: every episode, the reference's)."""
BATCHES = tuple(int(b) for b in os.environ.get("CUDA_CHECK_BATCHES", "256,2000").split(","))
"""The batch sizes of the rate rows."""
KS = tuple(int(k) for k in os.environ.get("CUDA_CHECK_KS", "1,16,64,256").split(","))
"""The slot counts K of the rate rows."""
UPDATE_TOLERANCE = 1e-5
"""CPU against CUDA after up to 1000 identical updates: the largest parameter difference over
the largest parameter magnitude (docs/performance.md, *On a GPU*)."""


def left() -> float:
    """Seconds left of the script's budget."""
    return BUDGET - (time.perf_counter() - T0)


def sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def starts(k: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Slot i's Actor and Critic from its own generator: slot 0 starts alike for every k."""
    rngs = [np.random.default_rng([seed, i]) for i in range(k)]
    thetas = np.stack([A_SPEC.initial(rng) for rng in rngs])
    omegas = np.stack([C_SPEC.initial(rng) for rng in rngs])
    return thetas, omegas


# ------------------------------------------------------------------------------ 1. updates
def update_rows(device: str, k: int = 4, batch: int = 2000, n: int = 1000) -> list[dict]:
    """Largest Actor/Critic differences between CPU and ``device`` learners after N updates
    on identical batches (drawn on the host, copied to both)."""
    hp = DDPGConfig(batch_size=batch)
    thetas, omegas = starts(k)
    learners = [
        make_learner(A_SPEC, C_SPEC, thetas, omegas, hp, torch.device(d)) for d in ("cpu", device)
    ]
    rng = np.random.default_rng(1)
    obs_size = ENV.observation_size
    rows, marks = [], {1, 10, 100, 1000, n}
    for step in range(1, n + 1):
        obs = rng.normal(size=(k, batch, obs_size)).astype(np.float32)
        batch_arrays = (
            obs,
            rng.uniform(size=(k, batch, ENV.n_carts)).astype(np.float32),
            rng.uniform(size=(k, batch, 1)).astype(np.float32),
            (obs + 0.05 * rng.normal(size=obs.shape)).astype(np.float32),
            np.ones((k, batch, 1), np.float32),
        )
        for learner in learners:
            learner.train(tuple(torch.from_numpy(a).to(learner.device) for a in batch_arrays))
        if step in marks:
            row = {"updates": step, "agents": k, "batch": batch}
            for name in ("actor", "critic"):
                cpu, dev = (getattr(learner, f"{name}_flat")() for learner in learners)
                diff = np.abs(cpu.astype(np.float64) - dev)
                row[f"{name} max |diff|"] = float(diff.max())
                row[f"{name} max |diff| / max |param|"] = float(diff.max() / np.abs(cpu).max())
            row["within tolerance"] = all(
                row[f"{name} max |diff| / max |param|"] <= UPDATE_TOLERANCE
                for name in ("actor", "critic")
            )
            rows.append(row)
            print(row, flush=True)
    return rows


# ------------------------------------------------------------------------------------ 2. K
def trainer(
    k: int, batch: int, device: str, warmup: int = 300, judge_every: int = 0
) -> SlotTrainer:
    hp = DDPGConfig(
        judge_every=judge_every,
        batch_size=batch,
        warmup_steps=warmup,
        max_steps=10**9,
        min_steps=10**9,
        patience_steps=10**9,
        device=device,
    )
    thetas, omegas = starts(k)
    return SlotTrainer(thetas, omegas, list(range(k)), ENV, hp)


def k_rows(device: str, steps: int, batch: int = 256, ks: tuple[int, ...] = (4, 16)) -> list[dict]:
    """Slot 0's Actor after ``steps`` lockstep steps alone and beside K - 1 other searches
    (slot 0 starts from the same parameters and seed in every K)."""
    actors = {}
    for k in (1, *ks):
        t = trainer(k, batch, device)
        for _ in range(steps):
            t.step()
        sync(device)
        actors[k] = t.learner.actor_flat(torch.tensor([0], device=t.device))[0]
    rows = []
    for k in ks:
        diff = np.abs(actors[k].astype(np.float64) - actors[1])
        rows.append(
            {
                "device": device,
                "steps": steps,
                "batch": batch,
                "K": k,
                "slot 0 identical to K=1": bool(np.array_equal(actors[k], actors[1])),
                "max |diff|": float(diff.max()),
            }
        )
        print(rows[-1], flush=True)
    return rows


def trial_rows(device: str, steps: int) -> list[dict]:
    """A tiny lockstep experiment (2 runs x 2 local searches of ``steps`` env steps) with one
    slot and with two: are the stored trials the same?"""
    import tempfile

    from lonlib.config import named_config
    from lonlib.experiment.running import run_experiment
    from lonlib.storage.trials import read_experiment_trials

    base = named_config("reference")
    ddpg = dataclasses.replace(
        base.ddpg,
        max_steps=steps,
        min_steps=steps // 2,
        patience_steps=steps // 4,
        warmup_steps=300,
        batch_size=256,
        buffer_size=4000,
        device=device,
    )
    config = dataclasses.replace(
        base, runs=2, perturbations=(1e-3,), max_local_searches=2, tolerance=1, ddpg=ddpg
    )
    trials = {}
    for slots in (1, 2):
        with tempfile.TemporaryDirectory() as folder:
            start = time.perf_counter()
            run_experiment(config, Path(folder), progress=False, executor="lockstep", slots=slots)
            print(f"slots={slots}: {time.perf_counter() - start:.1f} s", flush=True)
            trials[slots] = read_experiment_trials(Path(folder))
    columns = [
        c for c in ("fitness", "start_fitness", "env_steps", "accepted", "label") if c in trials[1]
    ]
    a, b = (trials[s].sort_values(["run", "index"])[columns].reset_index(drop=True) for s in (1, 2))
    row = {
        "device": device,
        "searches": len(a),
        "identical trials (slots 1 vs 2)": bool(a.equals(b)),
        "fitness slots=1": a["fitness"].tolist(),
        "fitness slots=2": b["fitness"].tolist(),
    }
    print(row, flush=True)
    return [row]


def k_growth_rows(device: str, marks: tuple[int, ...], batch: int = 256) -> list[dict]:
    """Where a search's CUDA trajectory starts to depend on K: slot 0's Actor at each of
    ``marks`` steps alone (K = 1), beside 3 others (K = 4), and at K = 4 again (is a fixed K
    repeatable?)."""
    snapshots: dict[str, dict[int, np.ndarray]] = {}
    for name, k in (("K=1", 1), ("K=4", 4), ("K=4 again", 4)):
        t = trainer(k, batch, device)
        snapshots[name] = {}
        for step in range(1, max(marks) + 1):
            t.step()
            if step in marks:
                rows = torch.tensor([0], device=t.device)
                snapshots[name][step] = t.learner.actor_flat(rows)[0].astype(np.float64)
    rows = []
    for step in marks:
        one, four, again = (snapshots[n][step] for n in ("K=1", "K=4", "K=4 again"))
        rows.append(
            {
                "device": device,
                "step": step,
                "updates": max(step - 299, 0),  # the first update is in step 300
                "K=4 vs K=1 max |diff|": float(np.abs(four - one).max()),
                "K=4 twice identical": bool(np.array_equal(four, again)),
            }
        )
        print(rows[-1], flush=True)
    return rows


def greedy_rows(count: int = 256) -> list[dict]:
    """Host-side greedy rollouts of stored optima (data/reference, a mix of behaviours):
    seconds per policy in one batched rollout of ``count``, and alone."""
    from lonlib.config import DDPGConfig as Config
    from lonlib.ddpg.trainer import greedy_scores

    files = sorted(Path("data/reference").glob("p=*/run_*/optimum_*.npz"))
    if not files:
        return [{"error": "no stored optima under data/reference"}]
    thetas = np.stack([np.load(f)["theta"] for f in files])
    thetas = thetas[np.arange(count) % len(thetas)]
    scoring = Config().scoring
    rows = []
    for m in sorted({1, min(16, count), count}):
        start = time.perf_counter()
        greedy_scores(thetas[:m], ENV, scoring)
        seconds = time.perf_counter() - start
        rows.append({"policies": m, "seconds": seconds, "s per policy": seconds / m})
        print(rows[-1], flush=True)
    return rows


# -------------------------------------------------------------------------------- 3. rates
def rate_row(k: int, batch: int, device: str, episode: int) -> dict:
    """Agent-steps per second of ``k`` slots over one training episode past the warm-up,
    and the share of that time in the host-side greedy rollouts."""
    t = trainer(k, batch, device, judge_every=JUDGE_EVERY)
    judged = {"seconds": 0.0, "calls": 0, "policies": 0}
    judge = t._judge_pending

    def timed_judge() -> None:
        judged["policies"] += len(t.pending)
        start = time.perf_counter()
        judge()
        judged["seconds"] += time.perf_counter() - start
        judged["calls"] += 1

    t._judge_pending = timed_judge
    warm = t.hp.warmup_steps + 20
    for _ in range(warm):
        t.step()
    sync(device)
    judged.update(seconds=0.0, calls=0, policies=0)
    start, steps = time.perf_counter(), 0
    while steps < episode:
        t.step()
        steps += 1
    sync(device)
    seconds = time.perf_counter() - start
    rate = k * steps / seconds
    return {
        "device": device if device == "cpu" else torch.cuda.get_device_name(),
        "batch": batch,
        "K": k,
        "judge_every": JUDGE_EVERY,
        "steps": steps,
        "agent-steps/s": rate,
        "ms per step": 1e3 * seconds / steps,
        "greedy share": judged["seconds"] / seconds,
        "greedy policies": judged["policies"],
        "greedy s per policy": judged["seconds"] / max(judged["policies"], 1),
    }


def rate_rows(
    device: str, ks: tuple[int, ...], batches: tuple[int, ...], episode: int
) -> list[dict]:
    rows = []
    for batch in batches:
        for k in ks:
            if left() < 60:
                print(f"skipped K={k} batch {batch}: time", flush=True)
                continue
            rows.append(rate_row(k, batch, device, episode))
            print(rows[-1], flush=True)
    return rows


# ------------------------------------------------------------------------------ 4. profile
def profile_rows(device: str, k: int, batch: int, out: Path) -> list[dict]:
    """One lockstep step at ``k`` slots under torch's profiler after 60 unprofiled steps (warm-up
    50, so 11 updates in; at K = 200 no training episode has ended yet, so the step has no
    event copies and no greedy rollouts), then the wall time of 20 unprofiled steps."""
    from torch.profiler import ProfilerActivity, profile

    t = trainer(k, batch, device, warmup=50)
    for _ in range(60):
        t.step()
    sync(device)
    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device != "cpu" else [])
    with profile(activities=activities) as prof:
        t.step()
        sync(device)
    try:
        table = prof.key_averages().table(
            sort_by="device_time_total" if device != "cpu" else "cpu_time_total", row_limit=30
        )
    except Exception:  # noqa: BLE001 - older torch names it cuda_time_total
        table = prof.key_averages().table(sort_by="cuda_time_total", row_limit=30)
    (out / "profile_step.txt").write_text(table)
    events = prof.events()
    names = [e.name for e in events]
    kernels = [
        e for e in events if getattr(e, "device_type", None) == torch.autograd.DeviceType.CUDA
    ]
    row = {
        "K": k,
        "batch": batch,
        "memcpy HtoD": sum("Memcpy HtoD" in n for n in names),
        "memcpy DtoH": sum("Memcpy DtoH" in n for n in names),
        "cudaLaunchKernel": sum(n == "cudaLaunchKernel" for n in names),
        "device events": len(kernels),
        "device time ms": sum(e.device_time_total for e in kernels) / 1e3 if kernels else 0.0,
    }
    start = time.perf_counter()
    for _ in range(20):
        t.step()
    sync(device)
    row["wall ms per step (20 steps, unprofiled)"] = 1e3 * (time.perf_counter() - start) / 20
    print(table[:3000], flush=True)
    print(row, flush=True)
    return [row]


# -------------------------------------------------------------------------------- 5. paper
def paper_rows(rates: list[dict]) -> list[dict]:
    """CONFIG=paper's wall time at the best measured batch-2000 rate (K = 256 stands in for
    the paper's 200 slots, the greedy rollouts included as measured)."""
    at = [r for r in rates if r["batch"] == 2000]
    if not at:
        return []
    best = max(at, key=lambda r: r["agent-steps/s"])
    return [
        {
            "rate from": f"{best['device']}, K = {best['K']}, batch 2000",
            "agent-steps/s": best["agent-steps/s"],
            "paper low [h]": PAPER_AGENT_STEPS["low"] / best["agent-steps/s"] / 3600,
            "paper high [h]": PAPER_AGENT_STEPS["high"] / best["agent-steps/s"] / 3600,
        }
    ]


def main(out: Path, smoke: bool) -> None:
    out.mkdir(parents=True, exist_ok=True)
    device = "cpu" if smoke else "cuda"
    results: dict = {
        "python": platform.python_version(),
        "torch": torch.__version__,
        "numpy": np.__version__,
        "device": torch.cuda.get_device_name() if device == "cuda" else "cpu (smoke)",
        "tf32 matmul": torch.backends.cuda.matmul.allow_tf32,
    }
    sizes = (
        {
            "updates": (2, 64, 12),
            "K": 30,
            "rates": ((1, 4), (256,), 40),
            "profile": (4, 64),
            "trials": 600,
        }
        if smoke
        else {
            "updates": (4, 2000, 1000),
            "K": 1500,
            "rates": (KS, BATCHES, 2000),
            "profile": (200, 2000),
            "trials": 3000,
        }
    )

    def save() -> None:
        (out / "cuda_check.json").write_text(json.dumps(results, indent=1, default=str))

    sections = {
        "updates": lambda: update_rows(device, *sizes["updates"]),
        "K": lambda: k_rows(device, sizes["K"]),
        "rates": lambda: rate_rows(device, *sizes["rates"]),
        "profile": lambda: profile_rows(device, *sizes["profile"], out),
        "trials": lambda: trial_rows(device, sizes["trials"]),
    }
    marks = (301, 302, 320) if smoke else (301, 302, 305, 320, 400, 700, 1500)
    sections["K growth"] = lambda: k_growth_rows(device, marks)
    sections["greedy"] = lambda: greedy_rows(8 if smoke else 256)
    sections["cpu rates"] = lambda: rate_rows("cpu", (1, 16), (256,), 40 if smoke else 2000)
    chosen = os.environ.get("CUDA_CHECK_SECTIONS")
    if chosen:
        sections = {n: sections[n] for n in chosen.split(",")}
    for name, section in sections.items():
        start = time.perf_counter()
        try:
            results[name] = section()
        except Exception:  # noqa: BLE001 - record and go on: one device call, every section
            results[name] = {"error": traceback.format_exc()}
            print(results[name]["error"], flush=True)
        results[f"{name} seconds"] = time.perf_counter() - start
        print(f"== {name}: {results[f'{name} seconds']:.1f} s, {left():.0f} s left", flush=True)
        save()
    if isinstance(results.get("rates"), list):
        results["paper"] = paper_rows(results["rates"])
        print(results["paper"], flush=True)
    save()


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    main(Path(args[0] if args else "cuda_check_out"), "--smoke" in sys.argv)
