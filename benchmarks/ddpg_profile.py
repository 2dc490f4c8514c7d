"""Where one DDPG update and one training step spend their time (one torch thread).

``python -m benchmarks.ddpg_profile`` prints, for each update implementation, batch size and
``k``, the operators issued per update and the top operators' shares of self time
(torch.profiler); a lower bound of the lean update from its work per sample and this
machine's fastest kernels; then a cProfile of a short ``local_search_batch`` at batch 256
split by the loop's direct callees. The committed summary is ``benchmarks/PROFILE.md``.
Profilers add their own per-call overhead, so read the shares, not the absolute times
(``python -m benchmarks`` measures those).
"""

from __future__ import annotations

import cProfile
import pstats
import time
from collections import defaultdict

import numpy as np
import torch
from torch.profiler import ProfilerActivity, profile

from benchmarks.ddpg import ENV, make_update
from lonlib.config import DDPGConfig
from lonlib.ddpg.search import local_search_batch
from lonlib.task.policy import actor_spec, critic_spec


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


def work_per_sample(n_carts: int = 2) -> dict[str, int]:
    """What one lean update computes per sample: multiply-adds shaped like a forward layer
    (``W @ h``; the bias is the ones row), multiply-adds of weight gradients (``dz @ h^T``,
    a long reduction over the batch), sigmoids, and sigmoid derivatives."""
    actor, critic = actor_spec(n_carts), critic_spec(n_carts)

    def back_through(spec):  # dh below every layer but the first (no bias column)
        return sum(fan_in * fan_out for fan_in, fan_out in spec.layers[1:])

    hidden = [sum(fan_out for _, fan_out in spec.layers[:-1]) for spec in (actor, critic)]
    return {
        # actor on s and s'; critic on (s, a), (s', mu'(s')) and (s, mu(s)); three dh passes
        "forward-shaped MACs": 2 * actor.n_params
        + 3 * critic.n_params
        + back_through(critic)
        + back_through(critic)
        + 20 * n_carts
        + back_through(actor),
        "weight-gradient MACs": actor.n_params + critic.n_params,
        "sigmoids": 2 * (hidden[0] + n_carts) + 3 * hidden[1],
        "sigmoid derivatives": 2 * hidden[1] + hidden[0] + n_carts,
    }


def _fastest_us(work, calls: int = 300) -> float:
    for _ in range(20):
        work()
    best = float("inf")
    for _ in range(calls):
        start = time.perf_counter()
        work()
        best = min(best, time.perf_counter() - start)
    return best * 1e6


def kernel_costs(batch: int) -> dict[str, float]:
    """Fastest single call [us] of a tiny operator (the per-operator overhead) and the extra
    time per unit of work [ns] of the update's kernels at this batch size (20-unit layers)."""
    h, w = torch.rand(1, 21, batch), torch.rand(1, 20, 21)
    z, grad = torch.rand(1, 20, batch), torch.empty(1, 20, 21)
    tiny = torch.rand(2)
    overhead = _fastest_us(lambda: tiny.add_(0.0), 2000)
    macs, elements = 20 * 21 * batch, 20 * batch

    def per_unit(work, units):
        return max(0.0, _fastest_us(work) - overhead) * 1e3 / units

    return {
        "operator overhead us": overhead,
        "forward-shaped ns/MAC": per_unit(lambda: torch.bmm(w, h, out=z), macs),
        "weight-gradient ns/MAC": per_unit(lambda: torch.bmm(z, h.transpose(1, 2), out=grad), macs),
        "sigmoid ns": per_unit(lambda: z.sigmoid_(), elements),
        "sigmoid derivative ns": per_unit(
            lambda: torch.ops.aten.sigmoid_backward.grad_input(z, h[:, :20], grad_input=z),
            elements,
        ),
    }


def floor_ms(batch: int, operators: int, cost: dict[str, float]) -> dict[str, float]:
    """A lower bound on one lean update (k = 1) from its work and this machine's fastest
    kernels (:func:`kernel_costs`): ``operators`` x overhead + each kind of work at its
    measured speed."""
    work = work_per_sample()
    parts = {
        "operator overhead": operators * cost["operator overhead us"] / 1e3,
        "forward-shaped matmuls": work["forward-shaped MACs"] * cost["forward-shaped ns/MAC"],
        "weight-gradient matmuls": work["weight-gradient MACs"] * cost["weight-gradient ns/MAC"],
        "sigmoids": work["sigmoids"] * cost["sigmoid ns"],
        "sigmoid derivatives": work["sigmoid derivatives"] * cost["sigmoid derivative ns"],
    }
    for name in list(parts)[1:]:
        parts[name] *= batch / 1e6
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
    work = work_per_sample()
    print(f"\n== lower bound of one lean update (k = 1); work per sample: {work}")
    for batch in (2000, 256):
        _, operators, _ = update_profile("lean", batch, 1)
        cost = kernel_costs(batch)
        parts = floor_ms(batch, operators, cost)
        detail = ", ".join(f"{name} {value:.3f}" for name, value in parts.items())
        print(f"batch {batch}: >= {sum(parts.values()):.3f} ms = {detail}")
        print("  kernel costs: " + ", ".join(f"{name} {value:.3g}" for name, value in cost.items()))
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
