"""How many runs each of the paper's claims needs, and what that scale costs.

:func:`power_table` sizes an experiment for each claim of :mod:`lonlib.analysis.claims` from its
smallest effect of interest (stated before the data, ``lonlib.analysis.claims.*_SOI*``): the
smallest number of units (sinks, runs, behaviour nodes, optima in 0.5-0.8) from which the
claim's own decision rule reaches its verdict with :data:`~lonlib.analysis.claims.POWER` (80 %) at
one-sided :data:`~lonlib.analysis.claims.ALPHA` (0.05) when the effect is exactly that large, then
runs per p and the cost of running both p values (the experiment's design: claim c needs
both) on this machine, on a 64-core Dask cluster and on one GPU. Deterministic: the
simulations draw from generators seeded with ``(POWER_SEED, n)``.

Per claim (effect of interest -> decision simulated or computed):

* a, typical sink peaks: sinks on three levels with shares
  :data:`~lonlib.analysis.claims.MULTIMODAL_SOI_SHARES` (0.45, 0.45, 0.10); *reproduced* needs the
  bootstrap's lower end >= 3, i.e. fewer than 3 typical peaks in at most ALPHA of the
  resamples. Simulation (seeded) of the sinks' counts per level, with the resamples'
  failure computed exactly under an idealisation: far-apart point levels, a level typical
  when a resample holds >= 2 of its sinks, levels independent, infinitely many resamples.
* b, the low basins' strength: sinks on the paper's five levels with weights
  :data:`~lonlib.analysis.claims.LOW_BASINS_SOI_WEIGHTS` (2, 2, 1, 1, 1); *reproduced* needs the
  Clopper-Pearson lower end (one-sided ALPHA) of the weakest low peak's share of its pair
  with the strongest other above 1/2. Simulation (seeded) of the counts; every
  level counted as a typical peak.
* c, smaller p better: Cliff's delta :data:`~lonlib.analysis.claims.SMALLER_P_SOI_DELTA` (0.47);
  Noether's (1987) formula for the one-sided Mann-Whitney test, runs per p =
  ``2 (z_(1-alpha) + z_power)^2 / (3 delta^2)`` (equal groups, P(X > Y) = (1 + delta) / 2),
  rounded up; the bootstrap interval's lower end (also required) is the same one-sided
  test at ALPHA, approximately.
* d, sparseness: a share :data:`~lonlib.analysis.claims.SPARSE_SOI_SHARE` (0.15) of multi-inward
  nodes against the allowed 0.05; the one-sided exact binomial test (*contradicted*),
  power computed exactly from the binomial distribution. Nodes per run: at most the
  accepted optima per run, :data:`OPTIMA_PER_RUN` (measured); nodes merge, so the runs
  are a lower bound.
* e, the gap: [0.6, 0.7) at :data:`~lonlib.analysis.claims.GAP_SOI_RATIO` (0.5) of its neighbours'
  mean, a share of 0.2 of the three intervals against a smooth 1/3; the one-sided exact
  binomial test (*reproduced*), power exact. Optima in 0.5-0.8 per run:
  :data:`OPTIMA_PER_RUN` x :data:`GAP_REGION_SHARE`, an assumption (the reference has none
  there: at its rate no number of runs suffices).

For the exact binomial powers (sawtooth in n) and the simulated ones, the units needed are
the smallest n from which the power stays at or above 80 % up to :data:`MAX_UNITS`.

Cost of ``2 x runs per p`` runs at :data:`ENV_STEPS_PER_RUN` env steps each (one agent
update per env step): this machine, measured (:data:`AGENT_STEPS_PER_CORE_SECOND` per core
on :data:`THIS_MACHINE_CORES` cores); a Dask cluster of :data:`CLUSTER_CORES` cores, an
extrapolation of the same per-core rate (never measured; a run is a sequential chain on
one core, so it takes at least one run's time); one GPU, from the lockstep rates measured on
an NVIDIA H200 (:data:`GPU_LOCKSTEP_RATES`, batch 2000, greedy rollouts included; issue 30):
the runs train as one batch of K = min(runs, :data:`GPU_MAX_SLOTS`) slots at the rate
interpolated in log K, and each run is a sequential chain in its slot.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pandas as pd
from scipy import stats

from lonlib.analysis.claims import (
    ALPHA,
    CONFIDENCE,
    GAP_SOI_RATIO,
    LOW_BASINS_SOI_WEIGHTS,
    MULTIMODAL_MIN_PEAKS,
    MULTIMODAL_SOI_SHARES,
    POWER,
    SMALLER_P_SOI_DELTA,
    SPARSE_MAX_SHARE,
    SPARSE_SOI_SHARE,
    TYPICAL_MIN_SINKS,
    clopper_pearson,
)

ENV_STEPS_PER_RUN = 15_358_854 / 20
"""Env steps per run, measured on ``data/reference``: 15.36M env steps in 2 x 10 runs
(~0.77M: about 10 local searches of ~76k steps)."""
AGENT_STEPS_PER_CORE_SECOND = 178.0
"""The paper's DDPG (batch 2000) on one core of this machine, measured on ``data/reference``:
15.36M env steps in at most 24 h of one core. Its sessions' ends were not recorded then, so
the time is bounded from above: each session start to the next when they lie less than 3 h
apart (a working session's length), the last session's 67 min from its log, and 3 h for the
one session whose next start came two days later. So this is a lower bound on the rate and
the costs built on it are upper bounds. The first reference ran at 145 per core (9.2M env
steps in 8 h 50 min on 2 cores shared with analyses and tests)."""
THIS_MACHINE_CORES = 2
CLUSTER_CORES = 64
"""The Dask cluster of the cost column: the same per-core rate on this many cores."""
GPU_LOCKSTEP_RATES = {1: 269.0, 16: 3179.0, 64: 7362.0, 256: 11684.0}
"""Lockstep agent-steps per second by K on one NVIDIA H200 at batch 2000 (the paper's
networks, two carts, greedy rollouts on the host included), measured 2026-11-27 by
``python -m benchmarks.cuda_check`` (``benchmarks/measured/cuda-h200-2026-11-27.json``)."""
GPU_MAX_SLOTS = 256
"""The largest K measured on the GPU: more runs than this train in batches of this size."""
P_VALUES = 2
"""The experiment runs both p values (claim c compares them), so its cost is twice the
runs per p."""
OPTIMA_PER_RUN = 32 / 10
"""Accepted optima (the LON's nodes) per run, measured on ``data/reference`` at p = 1e-4:
32 in 10 runs. Converts claim d's behaviour nodes (at most one per optimum) and claim e's
optima in 0.5-0.8 into runs."""
GAP_REGION_SHARE = 0.4
"""Assumed share of the optima that lie in 0.5-0.8: the paper's landscape, its optima
spread evenly over its five peaks, two of which (0.55, 0.72) lie there. The reference has
none there (0 of 32)."""
POWER_SIMULATIONS = 4000
"""Simulated experiments per n for claims a and b."""
POWER_SEED = 0
"""Seed of the power simulations (the generator for n is seeded with (POWER_SEED, n))."""
MAX_UNITS = 1000
"""The largest n the search for the units needed scans."""


def _tail() -> float:
    return (1 - CONFIDENCE) / 2


def power_multimodal(n: int, shares=MULTIMODAL_SOI_SHARES) -> float:
    """Probability that claim a is reproduced with ``n`` sinks on levels with ``shares``
    (simulation seeded with (POWER_SEED, n), idealised as in the module docstring)."""
    rng = np.random.default_rng([POWER_SEED, n])
    counts = rng.multinomial(n, np.asarray(shares) / np.sum(shares), POWER_SIMULATIONS)
    below = stats.binom.cdf(TYPICAL_MIN_SINKS - 1, n, counts / n)  # a level's resample < 2
    fewer = 1 - np.prod(1 - below, axis=1)  # P*(fewer than all levels typical)
    if len(shares) < MULTIMODAL_MIN_PEAKS:
        return 0.0
    return float(np.mean(fewer < _tail()))


def power_low_basins(n: int, weights=LOW_BASINS_SOI_WEIGHTS) -> float:
    """Probability that claim b is reproduced with ``n`` sinks on levels with ``weights``
    (the lowest half first; simulation seeded with (POWER_SEED, n))."""
    rng = np.random.default_rng([POWER_SEED, n])
    counts = rng.multinomial(n, np.asarray(weights) / np.sum(weights), POWER_SIMULATIONS)
    n_low = len(weights) // 2
    weak, strong = counts[:, :n_low].min(axis=1), counts[:, n_low:].max(axis=1)
    # The interval depends only on (weak, weak + strong): computed once per distinct pair.
    total = np.maximum(weak + strong, 1)
    keys, inverse = np.unique(weak * (n + 2) + total, return_inverse=True)
    low = clopper_pearson(keys // (n + 2), keys % (n + 2), CONFIDENCE)[0][inverse]
    return float(np.mean((low > 0.5) & (weak + strong > 0)))


def runs_smaller_p_better(delta: float = SMALLER_P_SOI_DELTA) -> int:
    """Runs per p for claim c (Noether's formula, see the module docstring)."""
    z = stats.norm.ppf(1 - ALPHA) + stats.norm.ppf(POWER)
    return math.ceil(2 * z**2 / (3 * delta**2))


def power_binomial(n: np.ndarray, null: float, true: float, alternative: str) -> np.ndarray:
    """Power of the one-sided exact binomial test of ``n`` trials (``"greater"``: share
    above ``null``; ``"less"``: below it) at ALPHA when the share is ``true``."""
    n = np.asarray(n)
    k = np.arange(n.max() + 1)[None, :]
    if alternative == "greater":
        reject = stats.binom.sf(k - 1, n[:, None], null) < ALPHA  # P(X >= k) < ALPHA
        mass = stats.binom.pmf(k, n[:, None], true)
    else:
        reject = stats.binom.cdf(k, n[:, None], null) < ALPHA  # P(X <= k) < ALPHA
        mass = stats.binom.pmf(k, n[:, None], true)
    return np.where(k <= n[:, None], reject * mass, 0.0).sum(axis=1)


def units_needed(power: np.ndarray, first: int) -> int:
    """The smallest n (``power[i]`` is the power at ``first + i``) from which the power
    stays at or above :data:`POWER`; -1 when it never does."""
    short = np.flatnonzero(np.asarray(power) < POWER)
    if len(short) == 0:
        return first
    if short[-1] == len(power) - 1:
        return -1
    return first + int(short[-1]) + 1


def _scan(power_at, first: int = 2) -> tuple[int, float]:
    """Units needed by a per-n power function, scanning up to :data:`MAX_UNITS` (stopping
    once the power has stayed above :data:`POWER` for 50 values in a row)."""
    values, streak = [], 0
    for n in range(first, MAX_UNITS + 1):
        values.append(power_at(n))
        streak = streak + 1 if values[-1] >= POWER else 0
        if streak >= 50:
            break
    needed = units_needed(np.array(values), first) if streak >= 50 else -1
    return needed, (values[needed - first] if needed > 0 else float("nan"))


def cost(runs_per_p: float) -> dict[str, float]:
    """Env steps, core-hours and wall hours (this machine, the cluster, one GPU) of
    ``runs_per_p`` runs at each of :data:`P_VALUES` p values."""
    runs = P_VALUES * runs_per_p
    steps = runs * ENV_STEPS_PER_RUN
    core_hours = steps / AGENT_STEPS_PER_CORE_SECOND / 3600
    run_hours = ENV_STEPS_PER_RUN / AGENT_STEPS_PER_CORE_SECOND / 3600
    return {
        "runs_total": runs,
        "env_steps_M": steps / 1e6,
        "core_hours": core_hours,
        "this_machine_hours": core_hours / THIS_MACHINE_CORES,
        "dask_64_hours": max(core_hours / CLUSTER_CORES, run_hours) if runs > 0 else core_hours,
        "gpu_hours": gpu_hours(runs),
    }


def gpu_lockstep_rate(slots: float) -> float:
    """Agent-steps per second of a lockstep batch of ``slots`` searches on the measured GPU
    (:data:`GPU_LOCKSTEP_RATES`, interpolated linearly in log K; at most
    :data:`GPU_MAX_SLOTS`)."""
    ks = np.array(sorted(GPU_LOCKSTEP_RATES), dtype=float)
    rates = np.array([GPU_LOCKSTEP_RATES[int(k)] for k in ks])
    return float(np.interp(np.log(min(max(slots, 1.0), GPU_MAX_SLOTS)), np.log(ks), rates))


def gpu_hours(runs: float) -> float:
    """Wall hours of ``runs`` runs of :data:`ENV_STEPS_PER_RUN` env steps on one GPU: one
    lockstep batch of K = min(runs, :data:`GPU_MAX_SLOTS`) slots, each slot a run at
    ``rate(K) / K`` agent-steps per second, ``ceil(runs / K)`` batches one after another."""
    if math.isnan(runs):  # a claim not reached within MAX_UNITS (power_table's NaN runs)
        return float("nan")
    if runs <= 0:
        return 0.0
    runs = math.ceil(runs - 1e-9)  # whole runs: a fraction of a run still takes a slot
    slots = min(runs, GPU_MAX_SLOTS)
    per_slot = gpu_lockstep_rate(slots) / slots
    return math.ceil(runs / slots) * ENV_STEPS_PER_RUN / per_slot / 3600


@lru_cache(maxsize=1)
def _rows() -> tuple[dict, ...]:
    soi_d, soi_e = SPARSE_SOI_SHARE, GAP_SOI_RATIO / (GAP_SOI_RATIO + 2)
    grid = np.arange(1, MAX_UNITS + 1)
    power_d = power_binomial(grid, SPARSE_MAX_SHARE, soi_d, "greater")
    power_e = power_binomial(grid, 1 / 3, soi_e, "less")
    nodes, optima = units_needed(power_d, 1), units_needed(power_e, 1)
    sinks_a, power_a = _scan(power_multimodal)
    sinks_b, power_b = _scan(power_low_basins)
    runs_c = runs_smaller_p_better()
    z = stats.norm.ppf(1 - ALPHA)
    power_c = stats.norm.cdf(math.sqrt(1.5 * runs_c) * SMALLER_P_SOI_DELTA - z)
    gap_per_run = OPTIMA_PER_RUN * GAP_REGION_SHARE
    shares = ", ".join(f"{s:g}" for s in MULTIMODAL_SOI_SHARES)
    weights = ":".join(str(w) for w in LOW_BASINS_SOI_WEIGHTS)
    return (
        {
            "claim": "a",
            "effect_of_interest": f"three sink levels with shares {shares} (weakest: one "
            "run in ten)",
            "decision": "bootstrap lower end of the typical peaks >= 3",
            "method": f"simulation, seed {POWER_SEED}, {POWER_SIMULATIONS} per n "
            "(idealised levels)",
            "unit": "sinks (one per run)",
            "units_needed": sinks_a,
            "power": power_a,
            "units_per_run": 1.0,
        },
        {
            "claim": "b",
            "effect_of_interest": f"five sink levels weighted {weights}: each low basin "
            "twice as strong (ratio 2)",
            "decision": "Clopper-Pearson lower end of the weakest low peak's share of "
            "its pair with the strongest other > 1/2",
            "method": f"simulation, seed {POWER_SEED}, {POWER_SIMULATIONS} per n",
            "unit": "sinks (one per run)",
            "units_needed": sinks_b,
            "power": power_b,
            "units_per_run": 1.0,
        },
        {
            "claim": "c",
            "effect_of_interest": f"Cliff's delta {SMALLER_P_SOI_DELTA} (large, Romano et "
            "al. 2006)",
            "decision": "one-sided Mann-Whitney p < 0.05 (and the bootstrap lower end > 0)",
            "method": "formula (Noether 1987)",
            "unit": "runs per p",
            "units_needed": runs_c,
            "power": float(power_c),
            "units_per_run": 1.0,
        },
        {
            "claim": "d",
            "effect_of_interest": f"{soi_d:.0%} of the behaviour nodes multi-inward "
            f"(allowed: {SPARSE_MAX_SHARE:.0%})",
            "decision": "one-sided exact binomial test of the share > 5 % (contradicted)",
            "method": "formula (exact binomial)",
            "unit": "behaviour nodes",
            "units_needed": nodes,
            "power": float(power_d[nodes - 1]),
            "units_per_run": OPTIMA_PER_RUN,
        },
        {
            "claim": "e",
            "effect_of_interest": f"[0.6, 0.7) at {GAP_SOI_RATIO:g} of its neighbours' mean "
            f"(share {soi_e:.2f} of 0.5-0.8, smooth: 1/3)",
            "decision": "one-sided exact binomial test of the share < 1/3 (reproduced)",
            "method": "formula (exact binomial)",
            "unit": "optima in 0.5-0.8",
            "units_needed": optima,
            "power": float(power_e[optima - 1]),
            "units_per_run": gap_per_run,
        },
    )


def power_table() -> pd.DataFrame:
    """One row per claim: the smallest effect of interest, the decision it must reach, how
    the power was computed (``method``), the units the test counts and how many it needs
    (``units_needed``, ``power`` there; -1 and NaN runs when not reached within
    :data:`MAX_UNITS`), units per run, ``runs_per_p``, and the cost of
    running both p values at that scale (``runs_total``, ``env_steps_M``, ``core_hours``,
    ``this_machine_hours``, ``dask_64_hours``, ``gpu_hours``; see the module
    docstring for what is measured, extrapolated and estimated)."""
    rows = []
    for row in _rows():
        if row["units_needed"] < 0:  # not reached within MAX_UNITS
            rows.append({**row, "runs_per_p": float("nan"), **cost(float("nan"))})
            continue
        runs = math.ceil(row["units_needed"] / row["units_per_run"] - 1e-9)
        rows.append({**row, "runs_per_p": runs, **cost(runs)})
    return pd.DataFrame(rows)
