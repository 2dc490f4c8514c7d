"""The power table (lonlib.analysis.claims_power): deterministic, more runs for a smaller effect,
power rising with n, and the cost columns following the documented rates."""

import math

import numpy as np
import pandas as pd
import pytest

from lonlib.analysis import claims_power
from lonlib.analysis.claims_power import (
    AGENT_STEPS_PER_CORE_SECOND,
    ENV_STEPS_PER_RUN,
    GPU_LOCKSTEP_RATES,
    cost,
    power_binomial,
    power_low_basins,
    power_multimodal,
    power_table,
    runs_smaller_p_better,
    units_needed,
)


def test_the_table_has_a_row_per_claim_and_is_deterministic():
    table = power_table()
    assert list(table["claim"]) == ["a", "b", "c", "d", "e"]
    claims_power._rows.cache_clear()
    pd.testing.assert_frame_equal(power_table(), table)
    assert (table["power"] >= 0.8).all() and (table["runs_per_p"] > 0).all()
    assert list(table["runs_per_p"]) == [66, 238, 19, 19, 62]
    assert table.loc[table["claim"] == "c", "method"].item() == "formula (Noether 1987)"
    d = table.set_index("claim").loc["d"]
    assert d["runs_per_p"] == math.ceil(d["units_needed"] / d["units_per_run"])


def test_a_smaller_effect_needs_more_runs():
    assert runs_smaller_p_better(0.3) > runs_smaller_p_better(0.47) > runs_smaller_p_better(0.8)
    grid = np.arange(1, 400)
    weak = units_needed(power_binomial(grid, 0.05, 0.10, "greater"), 1)
    strong = units_needed(power_binomial(grid, 0.05, 0.15, "greater"), 1)
    assert weak > strong > 0
    dip = units_needed(power_binomial(grid, 1 / 3, 0.25, "less"), 1)
    deep = units_needed(power_binomial(grid, 1 / 3, 0.20, "less"), 1)
    assert dip > deep > 0
    n = 66
    assert power_multimodal(n, (0.475, 0.475, 0.05)) < power_multimodal(n, (0.45, 0.45, 0.10))
    assert power_low_basins(150, (3, 3, 2, 2, 2)) < power_low_basins(150, (2, 2, 1, 1, 1))


def test_power_rises_with_n_and_is_seeded():
    assert power_multimodal(30) < power_multimodal(66) < power_multimodal(150)
    assert power_low_basins(60) < power_low_basins(238) < power_low_basins(500)
    assert power_multimodal(66) == power_multimodal(66)
    assert power_multimodal(66, (1.0, 0.0)) == 0.0  # two levels can never make three
    # exact binomial power: the sure cases
    assert power_binomial(np.array([200]), 0.05, 0.9, "greater")[0] == pytest.approx(1.0)
    assert power_binomial(np.array([200]), 0.05, 0.05, "greater")[0] < 0.05


def test_units_needed_waits_for_the_power_to_stay_up():
    assert units_needed(np.array([0.1, 0.85, 0.7, 0.81, 0.9]), 5) == 8
    assert units_needed(np.array([0.9, 0.95]), 3) == 3
    assert units_needed(np.array([0.9, 0.5]), 3) == -1


def test_cost_follows_the_documented_rates():
    row = cost(10)
    assert row["runs_total"] == 20
    assert row["env_steps_M"] == pytest.approx(20 * ENV_STEPS_PER_RUN / 1e6)
    core_hours = 20 * ENV_STEPS_PER_RUN / AGENT_STEPS_PER_CORE_SECOND / 3600
    assert row["core_hours"] == pytest.approx(core_hours)
    assert row["this_machine_hours"] == pytest.approx(core_hours / 2)
    one_run = ENV_STEPS_PER_RUN / AGENT_STEPS_PER_CORE_SECOND / 3600
    assert row["dask_64_hours"] == pytest.approx(one_run)  # 20 runs: one run's time
    assert cost(1000)["dask_64_hours"] == pytest.approx(2000 * one_run / 64)
    # 20 runs: one batch of K = 20, each slot at rate(20) / 20 (between K = 16 and 64)
    per_slot = row["gpu_hours"] * 3600 / ENV_STEPS_PER_RUN
    assert GPU_LOCKSTEP_RATES[64] / 64 < 1 / per_slot < GPU_LOCKSTEP_RATES[16] / 16
    assert cost(8)["gpu_hours"] == pytest.approx(
        ENV_STEPS_PER_RUN / (GPU_LOCKSTEP_RATES[16] / 16) / 3600
    )
    # 512 runs: two batches of 256 one after the other
    big = 2 * ENV_STEPS_PER_RUN / (GPU_LOCKSTEP_RATES[256] / 256) / 3600
    assert cost(256)["gpu_hours"] == pytest.approx(big)
    # 32 runs: K = 32, the rate halfway between K = 16 and 64 in log K
    halfway = (GPU_LOCKSTEP_RATES[16] + GPU_LOCKSTEP_RATES[64]) / 2
    assert cost(16)["gpu_hours"] == pytest.approx(ENV_STEPS_PER_RUN / (halfway / 32) / 3600)
    # 300 runs: K = 256, ceil(300 / 256) = 2 batches (not 300 / 256 of one, not one of 300)
    assert cost(150)["gpu_hours"] == pytest.approx(big)
    # half a run takes a slot as a whole run does; a claim never reached costs NaN
    assert cost(0.25)["gpu_hours"] == pytest.approx(cost(0.5)["gpu_hours"])
    assert math.isnan(cost(float("nan"))["gpu_hours"])
    assert one_run == pytest.approx(1.20, abs=0.01)  # 0.77M env steps at 178 per second


def test_gpu_rates_are_the_committed_measurement():
    import json
    from pathlib import Path

    measured = Path(__file__).parents[2] / "benchmarks/measured/cuda-h200-2026-11-27.json"
    rows = json.loads(measured.read_text())["rates"]
    at_2000 = {r["K"]: r["agent-steps/s"] for r in rows if r["batch"] == 2000}
    assert set(at_2000) == set(GPU_LOCKSTEP_RATES)
    for k, rate in GPU_LOCKSTEP_RATES.items():
        assert rate == pytest.approx(at_2000[k], abs=0.5)
