"""Where one DDPG update and one training step spend their time (one torch thread).

``python -m benchmarks.ddpg_profile`` prints, for each update implementation, batch size and
``k``, the self time of the torch operators grouped by kind (torch.profiler), then a cProfile
of a short ``local_search_batch`` at batch 256 split by what a training step does. The
committed summary is ``benchmarks/PROFILE.md``. Profilers add their own per-call overhead,
so read the shares, not the absolute times (``python -m benchmarks`` measures those).
"""

from __future__ import annotations

import cProfile
import pstats
from collections import defaultdict

import numpy as np
import torch
from torch.profiler import ProfilerActivity, profile

from benchmarks.ddpg import ENV, make_update
from lonlib.ddpg import DDPGConfig, local_search_batch
from lonlib.nets import actor_spec, critic_spec


def update_profile(kind: str, batch: int, k: int, updates: int = 30) -> tuple[float, int, dict]:
    """Profiled milliseconds of operator self time per update, operators issued per update
    and self time per operator [ms per update]."""
    one = make_update(kind, k, batch)
    for _ in range(5):
        one()
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(updates):
            one()
    by_op: dict[str, float] = defaultdict(float)
    for event in prof.key_averages():
        if event.key.startswith("aten::"):
            by_op[event.key.removeprefix("aten::")] += event.self_cpu_time_total / 1e3 / updates
    # Operators issued by Python or by the autograd engine, not from inside another operator.
    top_level = sum(
        1
        for event in prof.events()
        if event.name.startswith("aten::")
        and (event.cpu_parent is None or not event.cpu_parent.name.startswith("aten::"))
    )
    return sum(by_op.values()), top_level // updates, dict(by_op)


def step_profile(update: str, k: int = 1, steps: int = 3000) -> dict[str, float]:
    """Seconds spent in each direct callee of ``local_search_batch`` over ``steps`` training
    steps (batch 256, two carts, 500 warm-up steps), plus the loop's own time."""
    rng = np.random.default_rng(0)
    thetas = np.stack([actor_spec(2).initial(rng) for _ in range(k)])
    omegas = np.stack([critic_spec(2).initial(rng) for _ in range(k)])
    hp = DDPGConfig(
        batch_size=256,
        warmup_steps=500,
        max_steps=steps,
        min_steps=0,
        patience_steps=10**9,
        update=update,
    )
    profiler = cProfile.Profile()
    profiler.enable()
    local_search_batch(thetas, omegas, ENV, hp, seeds=list(range(k)))
    profiler.disable()
    stats = pstats.Stats(profiler).stats
    loop = next(key for key in stats if key[2] == "local_search_batch")
    parts: dict[str, float] = {"total": stats[loop][3], "loop body itself": stats[loop][2]}
    for (file, _, name), (*_, callers) in stats.items():
        if loop in callers:
            label = name if file == "~" else f"{name} ({file.rsplit('/', 1)[-1]})"
            parts[label] = parts.get(label, 0.0) + callers[loop][3]
    return parts


def main() -> None:
    """Print the update and training-step profiles."""
    torch.set_num_threads(1)
    print("== DDPG update: operator self time per update, top operators' shares (torch.profiler)")
    for kind in ("autograd", "lean"):
        for batch, k in ((2000, 1), (256, 1), (2000, 3), (256, 3)):
            total, calls, parts = update_profile(kind, batch, k)
            top = sorted(parts.items(), key=lambda kv: -kv[1])[:8]
            shares = ", ".join(f"{name} {value / total:.0%}" for name, value in top)
            print(f"{kind:8s} batch {batch:4d} k {k}: {total:.3f} ms, {calls:.0f} ops; {shares}")
    print("\n== local_search_batch, batch 256, 3000 steps (500 warm-up): cProfile seconds")
    for update in ("autograd", "lean"):
        for k in (1, 3):
            parts = step_profile(update, k)
            total = parts.pop("total")
            top = sorted(parts.items(), key=lambda kv: -kv[1])[:9]
            shares = ", ".join(f"{name} {value:.2f} s ({value / total:.0%})" for name, value in top)
            print(f"{update:8s} k {k}: {total:.2f} s; {shares}")


if __name__ == "__main__":
    main()
