"""The docs hold their numbers (issue 48, item 6): every number about stored results that
README.md and the docs pages state outside a generated block is checked here against the
committed data (``data/reference``, ``data/one-cart``, ``data/studies/*``), read through
lonlib's public functions, or against what lonlib's code computes (the reference
controllers).

Each entry of :data:`NUMBERS` is a page, a passage of it with ``{}`` fields in
:meth:`str.format` syntax, and a function of the data giving the fields: the passage, its
fields filled in, must be on the page (whitespace and line breaks as any run of spaces).
Numbers are formatted as lonlib's generated tables format them (``f"{x:.3f}"``: on a fitness
of 0.2885 that is ``0.288``, so a tie written by hand the other way reads as 4 decimals on the
page). :data:`FACTS` are passages whose claim has no number to format (a verdict, "every run"):
the passage must be on the page and the predicate hold. Numbers about data that is not
committed (the first reference, in git history; the calibration study's folders; the quick
comparison), estimates made before a run, timings of a machine and the designs of the
pre-registered studies are not checked; the pages say which is which.

To add one: quote the passage, replace its numbers by format fields and give the function
that computes them from the committed data; run this file.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lonlib.analysis import StoredExperiment, detect_peaks, power_table
from lonlib.analysis.claims import (
    BEHAVIOUR_NODE_EPSILON,
    SMALLER_P_SOI_DELTA,
    claim_d_curve,
    claim_multimodal,
    claims_from_trials,
    typical_peaks,
)
from lonlib.analysis.claims_rescored import rescore_trials
from lonlib.analysis.holding import hold_measures
from lonlib.analysis.landscape import landscapes
from lonlib.analysis.peaks import PAPER_PEAKS, compare_with_paper
from lonlib.analysis.reference_controllers import noisy_score, nominal_score
from lonlib.analysis.summary import behaviour_counts
from lonlib.calibration.cell_store import read_cell
from lonlib.calibration.imitation import load_imitation, load_teacher, pair_teacher
from lonlib.calibration.report import search_table
from lonlib.config import PendulumConfig, Scoring
from lonlib.config.calibration import load_calibration
from lonlib.storage import read_manifest
from lonlib.task import evaluate, run_actors, score_actors

ROOT = Path(__file__).parents[2]
REF, ONE = "data/reference", "data/one-cart"
WORDS = dict(
    enumerate(
        ["zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten"]
    )
)

# --- the committed data, through lonlib's public functions -----------------------------


@cache
def experiment(folder: str) -> StoredExperiment:
    return StoredExperiment.load(ROOT / folder)


def trials(folder: str) -> pd.DataFrame:
    return experiment(folder).trials


def accepted(folder: str, p: float | None = None) -> pd.DataFrame:
    rows = trials(folder)[trials(folder)["accepted"].astype(bool)]
    return rows if p is None else rows[np.isclose(rows["p"], p)]


def searches_per_run(folder: str) -> pd.Series:
    return trials(folder).groupby(["p", "run"]).size()


def best(folder: str, p: float | None = None) -> float:
    rows = trials(folder) if p is None else trials(folder)[np.isclose(trials(folder)["p"], p)]
    return float(rows["fitness"].max())


def env_steps(folder: str) -> int:
    return int(trials(folder)["env_steps"].sum())


def search_rates(folder: str) -> pd.Series:
    """Env steps per second of each search (its lockstep batch's wall time)."""
    return trials(folder)["env_steps"] / trials(folder)["seconds"]


def settings(folder: str):
    return experiment(folder).config


def sessions(folder: str) -> list[dict]:
    return read_manifest(ROOT / folder)["sessions"]


def retained(folder: str) -> pd.Series:
    """Robust mean over nominal fitness of the accepted optima above 0 (the stored robust
    estimate: 8 starts at noise 0.01, which ``lonlib verify`` replays)."""
    rows = accepted(folder)
    rows = rows[rows["fitness"] > 0]
    return (
        (rows["b_robust_mean"] / rows["fitness"])
        .rename(None)
        .to_frame("ratio")
        .assign(label=rows["label"])
    )


def by_label(folder: str) -> pd.DataFrame:
    return (
        accepted(folder)
        .groupby("label")
        .agg(
            optima=("fitness", "size"),
            nominal=("fitness", "median"),
            robust=("b_robust_mean", "median"),
            all_median=("b_fitness_all", "median"),
            mean_median=("b_fitness_mean", "median"),
        )
    )


@cache
def claims(folder: str) -> pd.DataFrame:
    return claims_from_trials(trials(folder)).set_index("claim")


@cache
def curve(folder: str) -> pd.DataFrame:
    return claim_d_curve(trials(folder))


def first_epsilon(folder: str, p: float, rule: Callable[[pd.DataFrame], pd.Series]) -> float:
    rows = curve(folder)[np.isclose(curve(folder)["p"], p)]
    return float(rows[rule(rows)]["epsilon"].min())


def curve_at(folder: str, p: float, epsilon: float) -> pd.Series:
    rows = curve(folder)
    return rows[np.isclose(rows["p"], p) & np.isclose(rows["epsilon"], epsilon)].iloc[0]


@cache
def landscape(folder: str, p: float):
    return experiment(folder).landscapes[p]


def typical(folder: str, p: float) -> pd.DataFrame:
    peaks = typical_peaks(landscape(folder, p).sink_fitness, 50)
    return peaks[peaks["typical"]]


def peaks_of(folder: str, p: float, column: str) -> list[float]:
    """The detected peaks nearest the paper's (as ``figures/peaks_aggregations.csv``)."""
    found = detect_peaks(accepted(folder, p)[column].to_numpy(), bins=50)
    return sorted(set(compare_with_paper(found)["nearest_detected"]))


@cache
def robust_sinks(folder: str, p: float) -> int:
    """Sinks of the LON re-scored with each node's robust mean (``lonlib.analysis
    .claims_rescored``), the stored robust means standing in for the replayed ones."""
    rows = accepted(folder)[["p", "run", "index", "b_robust_mean"]]
    rescored = rescore_trials(trials(folder), rows.rename(columns={"b_robust_mean": "robust_mean"}))
    return len(landscapes(rescored)[p].sink_fitness)


def final_incumbent_is_not_the_most_robust(folder: str) -> int:
    """Runs whose final incumbent is not their accepted optimum of highest robust mean."""
    count = 0
    for _, run in accepted(folder).groupby(["p", "run"]):
        final = run.sort_values("index").iloc[-1]
        count += bool(final["b_robust_mean"] != run["b_robust_mean"].max())
    return count


@cache
def power() -> pd.DataFrame:
    return power_table().set_index("claim")


def figures(folder: str, name: str) -> pd.DataFrame:
    """A table ``lonlib analyse`` stored under ``figures/`` (from replayed Actors: slow to
    recompute here; tests/project/test_docs.py ties the blocks made from them to the data)."""
    return pd.read_csv(ROOT / folder / "figures" / name)


def holding() -> pd.DataFrame:
    return figures(ONE, "holding.csv")


def retention(p: float) -> list[float]:
    rows = figures(REF, "retention.csv")
    rows = rows[np.isclose(rows["p"], p)]
    return [
        float(rows[np.isclose(rows["noise"], level)]["keep_share"].iloc[0])
        for level in (1e-6, 1e-5, 1e-4, 1e-3, 1e-2)
    ]


# the studies (data/studies/*): each cell's stored record, read as `lonlib calibrate` reads it


@cache
def study(name: str) -> tuple[pd.DataFrame, tuple[dict, ...]]:
    config = load_calibration(ROOT / "configs" / f"study-{name}.yaml")
    records = [read_cell(ROOT / "data" / "studies" / name, cell, config) for cell in config.cells]
    records = tuple(record for record in records if record)
    return search_table(list(records)), records


def proximity_span(name: str) -> float:
    """Metres of neighbour distance the proximity sensors S4/S5 span in a study's physics
    (``cart_width..tether_length``; their sensitivity per metre is its inverse)."""
    env = load_calibration(ROOT / "configs" / f"study-{name}.yaml").env
    return env.tether_length - env.cart_width


def cell(name: str, suffix: str = "height", motor: str = "velocity-tau0.02") -> pd.DataFrame:
    searches = study(name)[0]
    return searches[searches["cell"] == f"{motor}_semi-implicit_{suffix}"]


def slow_motor() -> pd.DataFrame:
    """Cell (iii)'s searches: the velocity motor at ``motor_gain`` 0.5, today's slack."""
    return cell("geometry-slow-motor", motor="velocity-tau0.02-gain0.5")


def swing_up_cells(name: str) -> pd.DataFrame:
    searches = study(name)[0]
    return searches[~searches["cell"].str.endswith("upright-start")]


def history(name: str, suffix: str, seed: int) -> dict:
    (record,) = [r for r in study(name)[1] if r["name"].endswith(f"_{suffix}")]
    return record["searches"][seed]


def episode_lengths(search: dict, quarter: int) -> float:
    """Mean training-episode length in one quarter of a search's 1M env steps."""
    ends = np.asarray(search["history_env_steps"], float)
    lengths = np.diff(np.concatenate([[0.0], ends]))
    inside = (ends > quarter * 250_000) & (ends <= (quarter + 1) * 250_000)
    return float(lengths[inside].mean())


def all_searches(name: str) -> list[dict]:
    return [search for record in study(name)[1] for search in record["searches"]]


def best_until(search: dict, steps: int | None = 750_000) -> float:
    """A search's best judged fitness ("all") up to ``steps`` env steps (None: all)."""
    judged = np.asarray(search["history_judged_env_steps"])
    fitness = np.asarray(search["history_fitness_all"])
    return float(fitness[judged <= (steps or judged.max())].max())


def late_gain(search: dict, after: int = 750_000) -> float:
    """How much a search's best judged fitness ("all") rose after ``after`` env steps."""
    return best_until(search, None) - best_until(search, after)


def reached(search: dict, value: float) -> int:
    """The env step of the first judged policy scoring ``value`` ("all")."""
    steps = np.asarray(search["history_judged_env_steps"])
    return int(steps[np.asarray(search["history_fitness_all"]) == value][0])


def first_if_best(search: dict) -> float | None:
    """A search's first judged fitness ("all") when nothing later beat it, else None."""
    first = search["history_fitness_all"][0]
    return first if best_until(search, None) == first else None


def left_zero(searches: pd.DataFrame) -> int:
    return int(searches["first_nonzero_steps"].notna().sum())


def kilo(steps: float) -> str:
    return f"{steps / 1000:.0f}k"


# the hold test's searches (data/studies/hold-test/runs/)


@cache
def hold_records() -> tuple[dict, ...]:
    from lonlib.calibration.hold import HoldTest, load_hold_config

    folder = ROOT / "data" / "studies" / "hold-test" / "runs"
    return tuple(HoldTest(load_hold_config(None), folder).records())


def hold(arm: str | None = None, p: float | None = None, carts: int | None = None) -> list[dict]:
    return [
        r
        for r in hold_records()
        if (arm is None or r["arm"] == arm)
        and (p is None or r["p"] == p)
        and (carts is None or r["n_carts"] == carts)
    ]


# the Gymnasium worked examples (data/gymnasium/)


@cache
def gym_trials(name: str) -> pd.DataFrame:
    from lonlib.storage.trials import read_finished_trials

    return read_finished_trials(ROOT / "data" / "gymnasium" / name)


def gym_metrics(name: str) -> pd.DataFrame:
    """Each p's LON metrics, computed from the stored trials (as ``lonlib analyse`` does)."""
    from lonlib.analysis.landscape import StoredExperiment
    from lonlib.lon.metrics import lon_metrics

    experiment = StoredExperiment.load(ROOT / "data" / "gymnasium" / name)
    rows = [{"p": p, **lon_metrics(land.graph)} for p, land in experiment.landscapes.items()]
    return pd.DataFrame(rows).set_index("p")


def gym_sampling_minutes(name: str) -> float:
    sessions = read_manifest(ROOT / "data" / "gymnasium" / name)["sessions"]
    return sum(s["seconds"] for s in sessions) / 60


def judged_near(record: dict, steps: int) -> float:
    """The judged fitness of a hold-test search nearest ``steps`` env steps."""
    at = int(np.argmin(np.abs(np.asarray(record["judged_env_steps"]) - steps)))
    return record["judged_fitness"][at]


def hold_row(arm: str, p: float) -> tuple:
    from lonlib.calibration.hold import load_hold_config, summarise

    records = hold(arm, p)
    table = summarise(list(records), load_hold_config(None))
    (row,) = table[(table["arm"] == arm) & (table["p"] == p)].itertuples()
    return (
        sum(r["last_judged_fitness"] >= 0.9 for r in records),
        row.late_share_mean,
        row.labels_at_end,
        float(np.median([r["judged_fitness"][0] for r in records])),
        max(r["max_judged_fitness"] for r in records),
        float(np.mean([r["returned_fitness"] for r in records])),
    )


# the hold test's imitation Actor (data/studies/hold-test/)


@cache
def imitation() -> tuple[np.ndarray, dict]:
    return load_imitation(ROOT / "data" / "studies" / "hold-test")


def imitation_env() -> PendulumConfig:
    return PendulumConfig.from_mapping(imitation()[1]["env"])


@cache
def imitation_episode():
    """The imitation Actor's traced episode from the nominal start."""
    return run_actors(imitation()[0][None, :], imitation_env(), trace=True)


@cache
def imitation_perturbed():
    """The imitation Actor from 16 starts perturbed by U[-0.01, 0.01] (as imitation scores it)."""
    return score_actors(
        imitation()[0][None, :], imitation_env(), Scoring(starts=16, noise=0.01), True
    )


@cache
def teacher_pair() -> float:
    """The one-cart teacher copied to both carts (lonlib.calibration.imitation)."""
    teacher = load_teacher(ROOT / imitation()[1]["config"]["teacher"])
    return float(evaluate(pair_teacher(teacher, imitation_env()), imitation_env()).fitness[0])


def teacher_trial() -> pd.Series:
    rows = trials(ONE)
    chosen = rows[np.isclose(rows["p"], 1e-4) & (rows["run"] == 6) & (rows["index"] == 7)]
    return chosen.iloc[0]


# --- the checked numbers ---------------------------------------------------------------


@dataclass(frozen=True)
class Number:
    page: str
    quote: str  # the passage, its numbers as str.format fields
    values: Callable[[], tuple]


@dataclass(frozen=True)
class Fact:
    page: str
    quote: str  # the passage, as on the page
    holds: Callable[[], bool]


def _swing(n: int):
    return nominal_score("swing-up", n)


NUMBERS = [
    # README.md
    Number(
        "README.md",
        "calibrated physics, {} × {} runs, every stored number replayed",
        lambda: (len(settings(REF).perturbations), settings(REF).runs),
    ),
    Number(
        "README.md",
        "no optimum lies above {:.3f}, below the paper's last peaks",
        lambda: (best(REF),),
    ),
    Number(
        "README.md",
        "keeping a median {:.0f} % of their fitness under tiny start noise",
        lambda: (100 * retained(REF)["ratio"].median(),),
    ),
    Number(
        "README.md",
        "None of the paper's claims is reproduced at {} runs per p",
        lambda: (settings(REF).runs,),
    ),
    Number(
        "README.md",
        "with a Cliff's delta of −{:.2f} and a 90 % interval of [−{:.2f}, +{:.2f}]",
        lambda: (
            -claims(REF).loc["c", "effect"],
            -claims(REF).loc["c", "ci_low"],
            claims(REF).loc["c", "ci_high"],
        ),
    ),
    Number(
        "README.md",
        "({} of its {} accepted optima hold the rod at {:.3f}–{:.3f}, every run's final "
        "incumbent among them",
        lambda: (
            int(holding()["holds"].sum()),
            len(holding()),
            holding()[holding()["holds"]]["fitness"].min(),
            holding()[holding()["holds"]]["fitness"].max(),
        ),
    ),
    Number(
        "README.md",
        "**the reference experiment** ({} × {} runs, T = {}, the paper's DDPG",
        lambda: (
            len(settings(REF).perturbations),
            settings(REF).runs,
            settings(REF).tolerance,
        ),
    ),
    Number(
        "README.md",
        "the one-cart LON (the paper's other problem, {} × {} runs of at most {} searches",
        lambda: (
            len(settings(ONE).perturbations),
            settings(ONE).runs,
            settings(ONE).max_local_searches,
        ),
    ),
    Number(
        "README.md",
        "every search {} env steps, its policy judged every {} env steps",
        lambda: (kilo(settings(ONE).ddpg.max_steps), settings(ONE).ddpg.judge_every),
    ),
    Number(
        "README.md",
        "the imitation Actor that balances both rods ({:.4f})",
        lambda: (imitation_episode().fitness[0],),
    ),
    Number(
        "README.md",
        "the two-cart learner-side study ({} cells × {} searches × {:.0f}M env steps;",
        lambda: (
            study("two-cart")[0]["cell"].nunique(),
            int(study("two-cart")[0].groupby("cell").size().max()),
            study("two-cart")[0]["env_steps"].max() / 1e6,
        ),
    ),
    # docs/results.md
    Number(
        "docs/results.md",
        "both p values, T = {}, at most {} local searches per run, the paper's DDPG (batch "
        "{}, buffer {}, ≤ {} env steps per search, patience {} after {})",
        lambda: (
            settings(REF).tolerance,
            settings(REF).max_local_searches,
            settings(REF).ddpg.batch_size,
            f"{settings(REF).ddpg.buffer_size:,}".replace(",", " "),
            kilo(settings(REF).ddpg.max_steps),
            kilo(settings(REF).ddpg.patience_steps),
            kilo(settings(REF).ddpg.min_steps),
        ),
    ),
    Number(
        "docs/results.md",
        "**Runs reduced, not the algorithm:** {} × {} runs against the paper's 100",
        lambda: (len(settings(REF).perturbations), settings(REF).runs),
    ),
    Number(
        "docs/results.md",
        "It ran in the background on one core across {} sessions, {} to {} (`lonlib run "
        "reference --workers 1`",
        lambda: (
            len(sessions(REF)),
            sessions(REF)[0]["started"][:10],
            sessions(REF)[-1]["started"][5:10],
        ),
    ),
    Number(
        "docs/results.md",
        "Measured: {:.1f}M env steps in {} local searches ({:.2f}M per run, {:.0f}k per "
        "search on average)",
        lambda: (
            env_steps(REF) / 1e6,
            len(trials(REF)),
            env_steps(REF) / len(searches_per_run(REF)) / 1e6,
            trials(REF)["env_steps"].mean() / 1e3,
        ),
    ),
    Number(
        "docs/results.md",
        "The manifest holds the {} sessions' starts",
        lambda: (len(sessions(REF)),),
    ),
    Number(
        "docs/results.md",
        "So the rate was at least {:.1f} agent-steps/s per core",
        lambda: (env_steps(REF) / (24 * 3600),),
    ),
    Number(
        "docs/results.md",
        "{:.0f}–{:.0f} env steps/s per search (median {:.0f}, in batches of up to 10",
        lambda: (search_rates(REF).min(), search_rates(REF).max(), search_rates(REF).median()),
    ),
    Number(
        "docs/results.md",
        "the training histories (~{:.0f} KB per search)",
        lambda: (
            np.mean([f.stat().st_size for f in (ROOT / REF).glob("p=*/run_*/history_*")]) / 1e3,
        ),
    ),
    Number(
        "docs/results.md",
        "Nothing lies above {:.3f}, below the paper's last peaks ({}, {}, {})",
        lambda: (best(REF), *PAPER_PEAKS[2:]),
    ),
    Number(
        "docs/results.md",
        "A run took {} to {} searches.",
        lambda: (searches_per_run(REF).min(), searches_per_run(REF).max()),
    ),
    Number(
        "docs/results.md",
        "replays every one of the {} trials from its stored Actor",
        lambda: (len(trials(REF)),),
    ),
    Number(
        "docs/results.md",
        "at the pre-registered ε = {} no two of the {} optima share a node",
        lambda: (BEHAVIOUR_NODE_EPSILON, len(accepted(REF, 1e-4))),
    ),
    Number(
        "docs/results.md",
        "on its curve the first optima merge at ε = {}, and at p = 1e-3, from ε = {} on, "
        "the share's interval lies above 5 % (*contradicted* there)",
        lambda: (
            first_epsilon(REF, 1e-4, lambda c: c["nodes"] < c["optima"]),
            first_epsilon(REF, 1e-3, lambda c: c["ci_low"] > 0.05),
        ),
    ),
    Number(
        "docs/results.md",
        "a is inconclusive at this n (one typical peak, at {:.2f} with {} of the {} sinks; "
        "the bootstrap interval [{:.0f}, {:.0f}] still reaches the paper's three; at p = "
        "1e-3, one typical peak, at {:.2f} with {} of {} sinks, interval [{:.0f}, {:.0f}]: "
        "*contradicted*)",
        lambda: (
            typical(REF, 1e-4)["fitness"].iloc[0],
            typical(REF, 1e-4)["support"].iloc[0],
            len(landscape(REF, 1e-4).sink_fitness),
            claims(REF).loc["a", "ci_low"],
            claims(REF).loc["a", "ci_high"],
            typical(REF, 1e-3)["fitness"].iloc[0],
            typical(REF, 1e-3)["support"].iloc[0],
            len(landscape(REF, 1e-3).sink_fitness),
            claim_multimodal(landscape(REF, 1e-3), 50).ci_low,
            claim_multimodal(landscape(REF, 1e-3), 50).ci_high,
        ),
    ),
    Number(
        "docs/results.md",
        "b is not testable: the {} sinks it needs are there",
        lambda: (len(landscape(REF, 1e-4).sink_fitness),),
    ),
    Number(
        "docs/results.md",
        "the power table's {} runs per p is what detecting b's effect would take",
        lambda: (power().loc["b", "runs_per_p"],),
    ),
    Number(
        "docs/results.md",
        "c is inconclusive at this n (Cliff's delta −{:.2f}, 90 % interval [−{:.2f}, "
        "+{:.2f}]: it leans against the paper, and its upper end lies below the smallest "
        "effect of interest, {}",
        lambda: (
            -claims(REF).loc["c", "effect"],
            -claims(REF).loc["c", "ci_low"],
            claims(REF).loc["c", "ci_high"],
            SMALLER_P_SOI_DELTA,
        ),
    ),
    Number(
        "docs/results.md",
        "keep a median {:.0f} % of their fitness, {:.0f} % keep less than half, and the "
        "spinning ones keep a median {:.0f} % of their fitness",
        lambda: (
            100 * retained(REF)["ratio"].median(),
            100 * (retained(REF)["ratio"] < 0.5).mean(),
            100 * retained(REF).query("label == 'spinning (independent)'")["ratio"].median(),
        ),
    ),
    Number(
        "docs/results.md",
        "`data/reference/recordings/` holds {} rerun recordings",
        lambda: (len(list((ROOT / REF / "recordings").glob("*.rrd"))),),
    ),
    Number(
        "docs/results.md",
        "so two independent spinners score ~{:.2f} under `all`",
        lambda: (by_label(REF).loc["spinning (independent)", "all_median"],),
    ),
    Number(
        "docs/results.md",
        "and ~{:.2f} under `mean`: under `mean` our spinners land near",
        lambda: (by_label(REF).loc["spinning (independent)", "mean_median"],),
    ),
    Number(
        "docs/results.md",
        "A policy that balances both rods scores ~{:.3f} under both, one that balances one "
        "rod and lets the other hang would score ~{:.2f} under `mean`",
        lambda: (imitation_episode().fitness_mean[0], imitation_episode().fitness_mean[0] / 2),
    ),
    Number(
        "docs/results.md",
        "(on the reference, {} of {} nodes with an upper end of {:.1f} %",
        lambda: (
            int(curve_at(REF, 1e-4, BEHAVIOUR_NODE_EPSILON)["multi_inward"]),
            int(curve_at(REF, 1e-4, BEHAVIOUR_NODE_EPSILON)["nodes"]),
            100 * curve_at(REF, 1e-4, BEHAVIOUR_NODE_EPSILON)["ci_high"],
        ),
    ),
    Number(
        "docs/results.md",
        "On the reference, the first two optima merge at ε = {} at p = 1e-4 ({} at p = "
        "1e-3) and the first node entered from two others appears at ε = {} ({}), far above "
        "the default 0.5; at ε = 2 it is {} of {} nodes ({} of {})",
        lambda: (
            first_epsilon(REF, 1e-4, lambda c: c["nodes"] < c["optima"]),
            first_epsilon(REF, 1e-3, lambda c: c["nodes"] < c["optima"]),
            first_epsilon(REF, 1e-4, lambda c: c["multi_inward"] > 0),
            first_epsilon(REF, 1e-3, lambda c: c["multi_inward"] > 0),
            int(curve_at(REF, 1e-4, 2.0)["multi_inward"]),
            int(curve_at(REF, 1e-4, 2.0)["nodes"]),
            int(curve_at(REF, 1e-3, 2.0)["multi_inward"]),
            int(curve_at(REF, 1e-3, 2.0)["nodes"]),
        ),
    ),
    Number(
        "docs/results.md",
        "at most {:.1f} behaviour nodes per run, the reference's accepted optima per run at "
        "p = 1e-4",
        lambda: (len(accepted(REF, 1e-4)) / settings(REF).runs,),
    ),
    Number(
        "docs/results.md",
        "Cost: {:.2f}M env steps per run (the reference: {:.1f}M in 2 × 10 runs)",
        lambda: (env_steps(REF) / len(searches_per_run(REF)) / 1e6, env_steps(REF) / 1e6),
    ),
    Number(
        "docs/results.md",
        "no search of the reference's batches exceeded {:.0f} env steps/s",
        lambda: (search_rates(REF).max(),),
    ),
    Number(
        "docs/results.md",
        "c needs {} runs per p ({:.0f}M env steps, ~{:.0f} h on this machine's two cores), "
        "d at least {}, e {} (were 40 % of the optima in 0.5–0.8), a {} and b {}",
        lambda: (
            power().loc["c", "runs_per_p"],
            power().loc["c", "env_steps_M"],
            power().loc["c", "this_machine_hours"],
            power().loc["d", "runs_per_p"],
            power().loc["e", "runs_per_p"],
            power().loc["a", "runs_per_p"],
            power().loc["b", "runs_per_p"],
        ),
    ),
    Number(
        "docs/results.md",
        "(on `data/reference`: {} sinks at p = 1e-4 against {})",
        lambda: (robust_sinks(REF, 1e-4), len(landscape(REF, 1e-4).sink_fitness)),
    ),
    Number(
        "docs/results.md",
        "(`robust_std` up to ~{:.2f} over its starts)",
        lambda: (accepted(REF)["b_robust_std"].max(),),
    ),
    Number(
        "docs/results.md",
        "`data/reference` these differ in {} of the {} runs",
        lambda: (final_incumbent_is_not_the_most_robust(REF), len(searches_per_run(REF))),
    ),
    # docs/one-cart.md
    Number(
        "docs/one-cart.md",
        "| runs per p, T | {}, {} |",
        lambda: (settings(ONE).runs, settings(ONE).tolerance),
    ),
    Number(
        "docs/one-cart.md",
        "| local searches per run | at most {} (`max_local_searches`)",
        lambda: (settings(ONE).max_local_searches,),
    ),
    Number(
        "docs/one-cart.md",
        "(its 20 runs ended by T = 5 after {}–{} searches, mean {:.1f}, median {:.1f})",
        lambda: (
            searches_per_run(REF).min(),
            searches_per_run(REF).max(),
            searches_per_run(REF).mean(),
            searches_per_run(REF).median(),
        ),
    ),
    Number(
        "docs/one-cart.md",
        "| local-search budget | {} env steps, every search its whole budget",
        lambda: (kilo(settings(ONE).ddpg.max_steps),),
    ),
    Number(
        "docs/one-cart.md",
        "| judged | every {} env steps (`judge_every`)",
        lambda: (settings(ONE).ddpg.judge_every,),
    ),
    Number(
        "docs/one-cart.md",
        "so it took the cap's {:.0f}M env steps (2 × 10 × 10 searches of 400k)",
        lambda: (env_steps(ONE) / 1e6,),
    ),
    Number(
        "docs/one-cart.md",
        "It sampled in the background across {} sessions ({} to {})",
        lambda: (
            WORDS[len(sessions(ONE))],
            sessions(ONE)[0]["started"][:10],
            sessions(ONE)[-1]["started"][:10],
        ),
    ),
    Number(
        "docs/one-cart.md",
        "(p = 1e-3, run 0: {:.4f} at each of its searches 1–9, all accepted",
        lambda: (trials(ONE).query("p == 0.001 and run == 0 and index == 1")["fitness"].iloc[0],),
    ),
    Number(
        "docs/one-cart.md",
        "close to the reference's run lengths ({}–{}, mean {:.1f})",
        lambda: (
            searches_per_run(REF).min(),
            searches_per_run(REF).max(),
            searches_per_run(REF).mean(),
        ),
    ),
    Number(
        "docs/one-cart.md",
        '(`"changed": {{"max_local_searches": [{}, {}]}}`)',
        lambda: next(
            tuple(s["changed"]["max_local_searches"]) for s in sessions(ONE) if "changed" in s
        ),
    ),
    Number(
        "docs/one-cart.md",
        "every run of both p took its {} searches ({} searches, {:.0f}M env steps)",
        lambda: (settings(ONE).max_local_searches, len(trials(ONE)), env_steps(ONE) / 1e6),
    ),
    Number(
        "docs/one-cart.md",
        "(best {:.2f} at p = 1e-3, the paper's upper peaks out of reach",
        lambda: (best(REF, 1e-3),),
    ),
    Number(
        "docs/one-cart.md",
        "(the {} of the {} accepted at p = 1e-3: {:.2f}–{:.2f})",
        lambda: (
            len(accepted(ONE, 1e-3).query("label == 'spinning'")),
            len(accepted(ONE, 1e-3)),
            accepted(ONE, 1e-3).query("label == 'spinning'")["fitness"].min(),
            accepted(ONE, 1e-3).query("label == 'spinning'")["fitness"].max(),
        ),
    ),
    Number(
        "docs/one-cart.md",
        "pile up at the top ({:.2f}–{:.3f}; {} more stops at a track end at {:.0f})",
        lambda: (
            accepted(ONE, 1e-3).query("label in ['swinging high', 'balancing']")["fitness"].min(),
            accepted(ONE, 1e-3).query("label in ['swinging high', 'balancing']")["fitness"].max(),
            WORDS[len(accepted(ONE, 1e-3).query("label == 'stops at boundary'"))],
            accepted(ONE, 1e-3).query("label == 'stops at boundary'")["fitness"].max(),
        ),
    ),
    # docs/study-geometry.md
    Number(
        "docs/study-geometry.md",
        "the best of the {} searches of `data/reference/` and of the {} swing-up searches of "
        "the [learner-side study](study-two-cart.md) is {:.3f}",
        lambda: (
            len(trials(REF)),
            len(swing_up_cells("two-cart")),
            max(best(REF), swing_up_cells("two-cart")["best_all"].max()),
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "(its upright-start cell, which starts at the top, reached {:.3f})",
        lambda: (cell("two-cart", "height_upright-start")["best_all"].max(),),
    ),
    Number(
        "docs/study-geometry.md",
        "(cell (i): {:.1f}× less than today)",
        lambda: (proximity_span("geometry-wide") / proximity_span("two-cart"),),
    ),
    Number(
        "docs/study-geometry.md",
        "our physics ({:.4f} through `run_actors`, trained by imitation)",
        lambda: (imitation_episode().fitness[0],),
    ),
    Number(
        "docs/study-geometry.md",
        "the one-cart optimum `data/one-cart/p=0.0001/run_0006/optimum_0007.npz` ({:.3f}, "
        "labelled *{}*)",
        lambda: (teacher_trial()["fitness"], teacher_trial()["label"]),
    ),
    Number(
        "docs/study-geometry.md",
        "act alike, and the pair scores {:.3f} on two carts",
        lambda: (teacher_pair(),),
    ),
    Number(
        "docs/study-geometry.md",
        "then {} rounds of the student's own episodes from the nominal start and {} starts "
        "perturbed by U[±{}], every visited state labelled by the teacher, binary "
        "cross-entropy, Adam, {:,} updates per round, torch on one thread, seed {})",
        lambda: (
            imitation()[1]["config"]["rounds"],
            imitation()[1]["config"]["starts"],
            imitation()[1]["config"]["noise"],
            imitation()[1]["config"]["updates"],
            imitation()[1]["config"]["seed"],
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "The committed Actor (round {}) scores **{:.4f}** from the nominal start (both rods "
        "up from step {} to {}, `{}`) and {:.4f} on each of {} starts perturbed by U[±{}]",
        lambda: (
            imitation()[1]["best_round"],
            imitation_episode().fitness[0],
            int(hold_measures(imitation_episode(), imitation_env())[1][0]),
            int(imitation_episode().end_step[0]),
            imitation_episode().end_reason_name(0),
            imitation_perturbed().robust_min[0],
            16,
            0.01,
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "(SHA-256 `{}…{}`)",
        lambda: (
            hashlib.sha256((ROOT / "data/studies/hold-test/actor.npy").read_bytes()).hexdigest()[
                :8
            ],
            hashlib.sha256((ROOT / "data/studies/hold-test/actor.npy").read_bytes()).hexdigest()[
                -7:
            ],
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "the rounds' scores are not monotone ({})",
        lambda: (", ".join(f"{r['fitness']}" for r in imitation()[1]["rounds"]),),
    ),
    Number(
        "docs/study-geometry.md",
        "| (i) wide slack | {} of {} (first non-zero at {}–{} env steps) | {:.4f} ({:.3f}) "
        "| {:.4f} | {} of {} | – | {} |",
        lambda: (
            left_zero(cell("geometry-wide")),
            len(cell("geometry-wide")),
            kilo(cell("geometry-wide")["first_nonzero_steps"].min()),
            kilo(cell("geometry-wide")["first_nonzero_steps"].max()),
            cell("geometry-wide")["best_all"].max(),
            cell("geometry-wide")["best_all"].median(),
            cell("geometry-wide")["best_mean"].max(),
            int(cell("geometry-wide")["first_090_all_steps"].notna().sum()),
            len(cell("geometry-wide")),
            behaviour_counts(cell("geometry-wide")["behaviour"]),
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "| (ii) intermediate slack | {} of {} (first non-zero at {}–{} env steps) | {:.4f} "
        "({:.3f}) | {:.4f} | {} of {} | – | {} |",
        lambda: (
            left_zero(cell("geometry-mid")),
            len(cell("geometry-mid")),
            kilo(cell("geometry-mid")["first_nonzero_steps"].min()),
            kilo(cell("geometry-mid")["first_nonzero_steps"].max()),
            cell("geometry-mid")["best_all"].max(),
            cell("geometry-mid")["best_all"].median(),
            cell("geometry-mid")["best_mean"].max(),
            int(cell("geometry-mid")["first_090_all_steps"].notna().sum()),
            len(cell("geometry-mid")),
            behaviour_counts(cell("geometry-mid")["behaviour"]),
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "Cell (ii), with {:.1f} m of slack between the two, does not balance either (best "
        "{:.4f}, every search spinning both rods)",
        lambda: (
            (env := load_calibration(ROOT / "configs/study-geometry-mid.yaml").env).tether_length
            - env.initial_spacing
            - env.cart_width,
            cell("geometry-mid")["best_all"].max(),
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "| (iii) slower motor | {} of {} (first non-zero at {}–{} env steps) | {:.4f} "
        "({:.3f}) | {:.4f} | {} of {} | – | {} |",
        lambda: (
            left_zero(slow_motor()),
            len(slow_motor()),
            kilo(slow_motor()["first_nonzero_steps"].min()),
            kilo(slow_motor()["first_nonzero_steps"].max()),
            slow_motor()["best_all"].max(),
            slow_motor()["best_all"].median(),
            slow_motor()["best_mean"].max(),
            int(slow_motor()["first_090_all_steps"].notna().sum()),
            len(slow_motor()),
            behaviour_counts(slow_motor()["behaviour"]),
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "Cell (iii), the velocity motor at `motor_gain` {:g} instead of {:g}, does not balance "
        "either (best {:.4f}; {})",
        lambda: (
            load_calibration(ROOT / "configs/study-geometry-slow-motor.yaml").cells[0].motor_gain,
            PendulumConfig().motor_gain,
            slow_motor()["best_all"].max(),
            behaviour_counts(slow_motor()["behaviour"]),
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "| (iv) upright start at (i) | {} of {} (judged > 0 from the first judgement, {} env "
        "steps) | {:.3f} ({:.3f}); the {:.3f} is a first judged policy, before training | "
        "{:.3f} | {} of {} | – | {} |",
        lambda: (
            left_zero(cell("geometry-wide", "height_upright-start")),
            len(cell("geometry-wide", "height_upright-start")),
            kilo(cell("geometry-wide", "height_upright-start")["first_nonzero_steps"].max()),
            cell("geometry-wide", "height_upright-start")["best_all"].max(),
            cell("geometry-wide", "height_upright-start")["best_all"].median(),
            history("geometry-wide", "upright-start", 0)["history_fitness_all"][0],
            cell("geometry-wide", "height_upright-start")["best_mean"].max(),
            int(cell("geometry-wide", "height_upright-start")["first_090_all_steps"].notna().sum()),
            len(cell("geometry-wide", "height_upright-start")),
            behaviour_counts(cell("geometry-wide", "height_upright-start")["behaviour"]),
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "| default geometry (the learner-side study's default cell, for comparison) | {} of "
        "{} | {:.3f} ({:.3f}) | {:.3f} | {} of {} | – | {} | – |",
        lambda: (
            left_zero(cell("two-cart")),
            len(cell("two-cart")),
            cell("two-cart")["best_all"].max(),
            cell("two-cart")["best_all"].median(),
            cell("two-cart")["best_mean"].max(),
            int(cell("two-cart")["first_090_all_steps"].notna().sum()),
            len(cell("two-cart")),
            behaviour_counts(cell("two-cart")["behaviour"]),
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "(best {:.4f}, the highest two-cart optimum yet, against {:.3f} in the reference)",
        lambda: (cell("geometry-wide")["best_all"].max(), best(REF)),
    ),
    Number(
        "docs/study-geometry.md",
        "The cell's best, {:.3f}, is search 0's *first* judged policy ({} env steps, the end of "
        "the warm-up: the random initial Actor started upright, its rods falling and turning, "
        "{:.1f} turns of the first rod, the carts colliding at step {:,}); training never beat "
        "it, and that search's last judged policy scores {:.3f}. Search 1's best is also its "
        "first ({:.4f}); searches 2 and 3 climb to {:.4f} (at {} env steps) and {:.3f} (at {}), "
        "about where the swing-up cells end. {} of the four best policies crash.",
        lambda: (
            (first := history("geometry-wide", "upright-start", 0))["history_fitness_all"][0],
            kilo(first["history_judged_env_steps"][0]),
            abs(
                (upright := cell("geometry-wide", "height_upright-start")).loc[
                    upright["best_all"].idxmax(), "turns_0"
                ]
            ),
            int(upright.loc[upright["best_all"].idxmax(), "end_step"]),
            first["history_fitness_all"][-1],
            first_if_best(history("geometry-wide", "upright-start", 1)),
            best_until(history("geometry-wide", "upright-start", 2), None),
            kilo(reached(h2 := history("geometry-wide", "upright-start", 2), best_until(h2, None))),
            best_until(history("geometry-wide", "upright-start", 3), None),
            kilo(reached(h3 := history("geometry-wide", "upright-start", 3), best_until(h3, None))),
            WORDS[int((upright["behaviour"] == "crash").sum())].capitalize(),
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "| `fresh` | 1e-4 | {} | not held | {:.2f} | {} | {:.3f} | {:.4f} | {:.3f} |",
        lambda: hold_row("fresh", 0.0001),
    ),
    Number(
        "docs/study-geometry.md",
        "| `fresh` | 1e-3 | {} | not held | {:.2f} | {} | {:.3f} | {:.4f} | {:.3f} |",
        lambda: hold_row("fresh", 0.001),
    ),
    Number(
        "docs/study-geometry.md",
        "| `fitted` | 1e-4 | {} | not held | {:.2f} | {} | {:.3f} | {:.4f} | {:.3f} |",
        lambda: hold_row("fitted", 0.0001),
    ),
    Number(
        "docs/study-geometry.md",
        "| `fitted` | 1e-3 | {} | not held | {:.2f} | {} | {:.3f} | {:.4f} | {:.3f} |",
        lambda: hold_row("fitted", 0.001),
    ),
    Number(
        "docs/study-geometry.md",
        "| `control` (one cart) | 1e-4 | {} | not held | {:.2f} | {} | {:.3f} | {:.4f} | {:.3f} |",
        lambda: hold_row("control", 0.0001),
    ),
    Number(
        "docs/study-geometry.md",
        "| `control` (one cart) | 1e-3 | {} | not held | {:.2f} | {} | {:.3f} | {:.4f} | {:.3f} |",
        lambda: hold_row("control", 0.001),
    ),
    Number(
        "docs/study-geometry.md",
        "each of the {} searches starts from a perturbed imitation Actor that still scores "
        "{:.4f}, and its first judged policy (after the first training episode past the "
        "{:,}-step warm-up, by env step {:,} at the latest) scores at most {:.4f}; no judged "
        "policy of any search gets back above {:.4f}, a fitted Critic (`fitted`) does not help, "
        "and the searches return {:.3f}–{:.3f} on average. **On one cart the balance "
        "fades:** the first judged policies score {:.3f}–{:.3f}, every search returns an "
        "optimum of at least {:.3f} (a basin-hopping chain stays at the top), and only later in "
        "a search does the policy drift off ({} of {} end at ≥ 0.9).",
        lambda: (
            len(hold(carts=2)),
            max(r["start_fitness"] for r in hold(carts=2)),
            2000,
            max(r["judged_env_steps"][0] for r in hold(carts=2)),
            max(r["judged_fitness"][0] for r in hold(carts=2)),
            max(r["max_judged_fitness"] for r in hold(carts=2)),
            min(hold_row(a, p)[5] for a in ("fresh", "fitted") for p in (1e-4, 1e-3)),
            max(hold_row(a, p)[5] for a in ("fresh", "fitted") for p in (1e-4, 1e-3)),
            min(r["judged_fitness"][0] for r in hold(carts=1)),
            max(r["judged_fitness"][0] for r in hold(carts=1)),
            min(r["returned_fitness"] for r in hold(carts=1)),
            sum(r["last_judged_fitness"] >= 0.9 for r in hold(carts=1)),
            len(hold(carts=1)),
        ),
    ),
    Number(
        "docs/study-geometry.md",
        "so the control's first judgement comes after {} update, while the two-cart\nones come "
        "after {}–{} updates; near {:,} env steps (about {:,} updates) only {} of the {}\n"
        "control searches still scores ≥ 0.9",
        lambda: (
            min(r["judged_env_steps"][0] for r in hold(carts=1)) - 2000 + 1,
            min(r["judged_env_steps"][0] for r in hold(carts=2)) - 2000 + 1,
            max(r["judged_env_steps"][0] for r in hold(carts=2)) - 2000 + 1,
            4000,
            2000,
            sum(judged_near(r, 4000) >= 0.9 for r in hold(carts=1)),
            len(hold(carts=1)),
        ),
    ),
    Number(
        "README.md",
        "the hold test's {} searches (finished: started on that Actor, DDPG loses the balance "
        "in its first training episode in all {} two-cart searches)",
        lambda: (
            len(hold()),
            sum(r["judged_fitness"][0] < 0.1 for r in hold(carts=2)),
        ),
    ),
    # docs/your-task.md
    Number(
        "docs/your-task.md",
        "2 × {} runs of at most {} local searches, {} local searches in all ({} at p = 0.001, {} "
        "at p = 0.0001), {:.2f}M env steps, sampled in {:.0f} minutes on one core. **Every run "
        "ends at the top:** each run's best optimum scores {:.4f}–{:.4f} (a greedy return of "
        "about {:.0f} from the evaluation start: the pendulum swung up and held), and {} of "
        "the {} optima score ≥ 0.9. Accepted steps improve the fitness only in the fourth or "
        "fifth decimal, so T = 5 rarely ends a run: {} of the {} runs took all {} local "
        "searches. Each p's LON has {} sinks, one per run, and {} funnels, {} of them global",
        lambda: (
            (t := gym_trials("pendulum-v1")).groupby("p")["run"].nunique().iloc[0],
            t.groupby(["p", "run"]).size().max(),
            len(t),
            int((t["p"] == 0.001).sum()),
            int((t["p"] == 0.0001).sum()),
            t["env_steps"].sum() / 1e6,
            gym_sampling_minutes("pendulum-v1"),
            (best := t.groupby(["p", "run"])["fitness"].max()).min(),
            best.max(),
            (best.max() - 1.0) * 3254.72,
            int((t["fitness"] >= 0.9).sum()),
            len(t),
            int((t.groupby(["p", "run"]).size() == 10).sum()),
            best.size,
            10,
            *{int(v) for v in gym_metrics("pendulum-v1")["sinks"]},
            *{int(v) for v in gym_metrics("pendulum-v1")["funnels"]},
            *{int(v) for v in gym_metrics("pendulum-v1")["global_funnels"]},
        ),
    ),
    Number(
        "docs/your-task.md",
        "2 × {} runs, {} local searches ({} per p), {:.2f}M env steps. **The deceptive optimum "
        "takes every run:** no optimum reaches the goal (the best scores {:.5f}, a return of "
        "almost exactly {:.0f}: the car stays put and spends almost no fuel; reaching the goal "
        "would score above 0.9), {} of the {} runs end at 0.4997 or above, and {} of the {} "
        "optima score below 0.49 (fuel spent without reaching the goal, down to {:.4f}). Each "
        "p's LON has {} sinks and {} funnels, {} of them global",
        lambda: (
            (t := gym_trials("mountaincar-continuous")).groupby("p")["run"].nunique().iloc[0],
            len(t),
            *{int(n) for n in t.groupby("p").size()},
            t["env_steps"].sum() / 1e6,
            t["fitness"].max(),
            abs(t["fitness"].max() * 199.9 - 99.9),
            int(((best := t.groupby(["p", "run"])["fitness"].max()) >= 0.4997).sum()),
            best.size,
            int((t["fitness"] < 0.49).sum()),
            len(t),
            t["fitness"].min(),
            *{int(v) for v in gym_metrics("mountaincar-continuous")["sinks"]},
            *{int(v) for v in gym_metrics("mountaincar-continuous")["funnels"]},
            *{int(v) for v in gym_metrics("mountaincar-continuous")["global_funnels"]},
        ),
    ),
    # docs/study-two-cart.md
    Number(
        "docs/study-two-cart.md",
        "none of this study's {} searches did even that",
        lambda: (len(study("two-cart")[0]),),
    ),
    Number(
        "docs/study-two-cart.md",
        "(the swing-up + balance controller scores {:.4f}) and on one cart",
        lambda: (_swing(2).fitness,),
    ),
    Number(
        "docs/study-two-cart.md",
        "scores {:.2f}–{:.2f} before its rods fall: {:.4f}, {:.3f}, {:.2f} and {:.2f} for "
        "this cell's four seeds",
        lambda: (
            *(s := sorted(cell("two-cart", "height_upright-start")["start_fitness"]))[::3],
            *s,
        ),
    ),
    Number(
        "docs/study-two-cart.md",
        "**Findings** ({} cells, {} searches of {:.0f}M env steps each at batch 256)",
        lambda: (
            WORDS[study("two-cart")[0]["cell"].nunique()],
            len(study("two-cart")[0]),
            study("two-cart")[0]["env_steps"].max() / 1e6,
        ),
    ),
    Number(
        "docs/study-two-cart.md",
        "the best policies of the four swing-up cells' {} searches spin their rods "
        'independently, crash or stop at a track end, at {:.2f} at most under "all rods '
        'upright" ({:.2f} under the per-pendulum mean)',
        lambda: (
            len(swing_up_cells("two-cart")),
            swing_up_cells("two-cart")["best_all"].max(),
            swing_up_cells("two-cart")["best_mean"].max(),
        ),
    ),
    Number(
        "docs/study-two-cart.md",
        "all four searches left zero, after {}–{} env steps, against {} of four after "
        "{}–{} in the default cell",
        lambda: (
            kilo(cell("two-cart", "height_explore")["first_nonzero_steps"].min()),
            kilo(cell("two-cart", "height_explore")["first_nonzero_steps"].max()),
            WORDS[left_zero(cell("two-cart"))],
            kilo(cell("two-cart")["first_nonzero_steps"].min()),
            kilo(cell("two-cart")["first_nonzero_steps"].max()),
        ),
    ),
    Number(
        "docs/study-two-cart.md",
        "stayed where the default's are ({:.3f} and {:.3f} against {:.3f} and {:.3f}; {:.3f} "
        "and {:.3f} against {:.3f} and {:.3f} under the per-pendulum mean)",
        lambda: tuple(
            getattr(cell("two-cart", suffix)[column], what)()
            for column in ("best_all", "best_mean")
            for suffix in ("height_explore", "height")
            for what in ("max", "median")
        ),
    ),
    Number(
        "docs/study-two-cart.md",
        "did worse: best {:.3f}, median {:.3f}, {} of four best policies crash",
        lambda: (
            cell("two-cart", "height-product")["best_all"].max(),
            cell("two-cart", "height-product")["best_all"].median(),
            WORDS[int((cell("two-cart", "height-product")["behaviour"] == "crash").sum())],
        ),
    ),
    Number(
        "docs/study-two-cart.md",
        "two searches improved by {:.2f}–{:.2f} ({:.4f} → {:.3f}, {:.3f} → {:.3f}), the one "
        "that started from a zero policy reached {:.4f}, and the best default search "
        "returned less than it started with ({:.3f} → {:.3f}",
        lambda: (
            (go := cell("two-cart", "height_continue").set_index("seed_index")).loc[3, "best_all"]
            - go.loc[3, "start_fitness"],
            go.loc[1, "best_all"] - go.loc[1, "start_fitness"],
            go.loc[1, "start_fitness"],
            go.loc[1, "best_all"],
            go.loc[3, "start_fitness"],
            go.loc[3, "best_all"],
            go.loc[2, "best_all"],
            go.loc[0, "start_fitness"],
            go.loc[0, "best_all"],
        ),
    ),
    Number(
        "docs/study-two-cart.md",
        "Two searches improved from first judged policies at {:.3f}–{:.3f} (their untrained "
        "Actors scored {:.2f} and {:.2f}) to {:.3f} and {:.3f} with policies whose rods spin "
        "({:.0f}–{:.0f} turns per rod; above horizontal in {:.0f}–{:.0f} % of the steps",
        lambda: (
            min(history("two-cart", "upright-start", i)["history_fitness_all"][0] for i in (0, 3)),
            max(history("two-cart", "upright-start", i)["history_fitness_all"][0] for i in (0, 3)),
            (up := cell("two-cart", "height_upright-start").set_index("seed_index")).loc[
                0, "start_fitness"
            ],
            up.loc[3, "start_fitness"],
            up.loc[0, "best_all"],
            up.loc[3, "best_all"],
            up.loc[[0, 3], ["turns_0", "turns_1"]].abs().min().min(),
            up.loc[[0, 3], ["turns_0", "turns_1"]].abs().max().max(),
            100 * up.loc[[0, 3], ["upright_share_0", "upright_share_1"]].min().min(),
            100 * up.loc[[0, 3], ["upright_share_0", "upright_share_1"]].max().max(),
        ),
    ),
    Number(
        "docs/study-two-cart.md",
        "the other two never improved on their first judged policy ({:.4f} and {:.4f})",
        lambda: tuple(
            cell("two-cart", "height_upright-start").set_index("seed_index").loc[[1, 2], "best_all"]
        ),
    ),
    Number(
        "docs/study-two-cart.md",
        "lasted {:.1f}–{:.1f} env steps on average in every quarter of the budget ({:.0f}k "
        "episodes in 1M env steps)",
        lambda: (
            min(
                episode_lengths(history("two-cart", "upright-start", i), q)
                for i in (1, 2)
                for q in range(4)
            ),
            max(
                episode_lengths(history("two-cart", "upright-start", i), q)
                for i in (1, 2)
                for q in range(4)
            ),
            cell("two-cart", "height_upright-start")
            .set_index("seed_index")
            .loc[[1, 2], "episodes"]
            .mean()
            / 1e3,
        ),
    ),
    Number(
        "docs/study-two-cart.md",
        "Late improvements are rare: {} of the {} searches improved after 750k env steps, "
        'by {:.4f}, {:.4f} and {:.3f} ("all rods upright"; the last is the default cell\'s '
        "best search, {:.4f} → {:.4f} between {} and {} env steps",
        lambda: (
            WORDS[sum(late_gain(search) > 0 for search in all_searches("two-cart"))],
            len(all_searches("two-cart")),
            *sorted(gain for search in all_searches("two-cart") if (gain := late_gain(search))),
            best_until(default_best := history("two-cart", "height", 0)),
            best_until(default_best, None),
            kilo(reached(default_best, best_until(default_best))),
            kilo(reached(default_best, best_until(default_best, None))),
        ),
    ),
    Number(
        "docs/study-two-cart.md",
        "balancing (the swing-up + balance controller scores {:.4f} on two carts)",
        lambda: (_swing(2).fitness,),
    ),
    # docs/rollout.md (its reference controllers' table is a generated block)
    Number(
        "docs/rollout.md",
        "and `lonlib verify` replays all {} committed trials (`data/reference`, `data/one-cart`)",
        lambda: (len(trials(REF)) + len(trials(ONE)),),
    ),
    Number(
        "docs/rollout.md",
        "and requires the stored fitness: {} of {} on `data/one-cart`; a sample of 40 of "
        "`data/reference`'s {} gave 40 of 40",
        lambda: (len(accepted(ONE)), len(accepted(ONE)), len(accepted(REF))),
    ),
    Number(
        "docs/rollout.md",
        "On the reference's accepted optima ({} at p = 1e-4, {} at 1e-3), replayed: under "
        "`all` (its LON's) the best are {:.3f} (p = 1e-4) and {:.3f} (1e-3), detected peaks "
        "near {:.2f} (1e-4) and {:.2f} and {:.2f} (1e-3); under `mean` the same episodes "
        "score up to {:.3f} and {:.3f}, peaks near {:.2f} and {:.2f} (1e-4) and {:.2f}, "
        "{:.2f} and {:.2f} (1e-3)",
        lambda: (
            len(accepted(REF, 1e-4)),
            len(accepted(REF, 1e-3)),
            accepted(REF, 1e-4)["b_fitness_all"].max(),
            accepted(REF, 1e-3)["b_fitness_all"].max(),
            *peaks_of(REF, 1e-4, "b_fitness_all"),
            *peaks_of(REF, 1e-3, "b_fitness_all"),
            accepted(REF, 1e-4)["b_fitness_mean"].max(),
            accepted(REF, 1e-3)["b_fitness_mean"].max(),
            *peaks_of(REF, 1e-4, "b_fitness_mean"),
            *peaks_of(REF, 1e-3, "b_fitness_mean"),
        ),
    ),
    Number(
        "docs/rollout.md",
        "that is today's `data/reference/`, on which `lonlib verify data/reference` passes "
        "with all {} trials replayed",
        lambda: (len(trials(REF)),),
    ),
    Number(
        "docs/rollout.md",
        "On the reference's accepted optima, replayed by the one rollout ({} per p with a "
        "nominal fitness above 0)",
        lambda: (int(retained(REF).groupby(accepted(REF)["p"]).size().max()),),
    ),
    Number(
        "docs/rollout.md",
        "| p = 1e-4 ({} optima) | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} |",
        lambda: (len(accepted(REF, 1e-4).query("fitness > 0")), *retention(1e-4)),
    ),
    Number(
        "docs/rollout.md",
        "| p = 1e-3 ({} optima) | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} |",
        lambda: (len(accepted(REF, 1e-3).query("fitness > 0")), *retention(1e-3)),
    ),
    Number(
        "docs/rollout.md",
        "*spinning (independent)* {} optima, median nominal {:.3f} → robust {:.4f}; *crash* "
        "{}, {:.3f} → {:.3f}; *stops at boundary* {}, {:.3f} → {:.3f}; *spinning (in "
        "phase)* {}, {:.3f} → {:.3f}",
        lambda: tuple(
            by_label(REF).loc[label, column]
            for label in (
                "spinning (independent)",
                "crash",
                "stops at boundary",
                "spinning (in phase)",
            )
            for column in ("optima", "nominal", "robust")
        ),
    ),
    # the reference controllers' scores named outside their table
    Number(
        "docs/model.md",
        "it scores, noise-free: {:.4f} on one cart and {:.4f} on two with semi-implicit Euler",
        lambda: (_swing(1).fitness, _swing(2).fitness),
    ),
    Number(
        "docs/model.md",
        "{:.4f} on one cart and {:.3f} on two with explicit Euler (a {} at step {})",
        lambda: (
            nominal_score("swing-up", 1, "euler").fitness,
            nominal_score("swing-up", 2, "euler").fitness,
            nominal_score("swing-up", 2, "euler").end_reason.lower(),
            nominal_score("swing-up", 2, "euler").end_step,
        ),
    ),
    Number(
        "docs/model.md",
        "({} starts, semi-implicit): {:.3f} mean on one cart, {:.3f} mean (median {:.0f}) on two",
        lambda: (
            len(noisy_score("swing-up", 1).fitness),
            noisy_score("swing-up", 1).mean,
            noisy_score("swing-up", 2).mean,
            noisy_score("swing-up", 2).median,
        ),
    ),
    Number(
        "docs/calibration.md",
        "balances under the chosen motor: {:.4f} on one cart, {:.4f} on two (noise-free;",
        lambda: (_swing(1).fitness, _swing(2).fitness),
    ),
]

FACTS = [
    Fact(
        "README.md",
        "None of the paper's claims is reproduced",
        lambda: "reproduced" not in set(claims(REF)["verdict"]),
    ),
    Fact(
        "README.md",
        "a (several typical sink levels), c (p = 1e-4 beats 1e-3",
        lambda: (
            claims(REF).loc[["a", "c", "d"], "verdict"].eq("inconclusive at this n").all()
            and claims(REF).loc[["b", "e"], "verdict"].eq("not testable at this scale").all()
        ),
    ),
    Fact(
        "README.md",
        "(no optimum in 0.5–0.8)",
        lambda: not accepted(REF)["fitness"].between(0.5, 0.8).any(),
    ),
    Fact(
        "README.md",
        "every run's final incumbent among them",
        lambda: all(
            holding()
            .set_index(["p", "run", "index"])
            .loc[(p, run, run_rows.sort_values("index")["index"].iloc[-1]), "holds"]
            for (p, run), run_rows in accepted(ONE).groupby(["p", "run"])
        ),
    ),
    Fact(
        "docs/results.md",
        "Every run left the zero plateau, and none balances a rod",
        lambda: (
            (trials(REF).groupby(["p", "run"])["fitness"].max() > 0).all()
            and not accepted(REF)["label"].isin(["balancing", "one rod up"]).any()
        ),
    ),
    Fact(
        "docs/results.md",
        "at the pre-registered ε = 0.5 no two of the 32 optima share a node",
        lambda: int(curve_at(REF, 1e-4, 0.5)["nodes"]) == len(accepted(REF, 1e-4)),
    ),
    Fact(
        "docs/results.md",
        "e is not testable (no optimum in 0.5–0.8)",
        lambda: claims(REF).loc["e", "verdict"] == "not testable at this scale",
    ),
    Fact(
        "docs/results.md",
        "interval [1, 2]: *contradicted*)",
        lambda: claim_multimodal(landscape(REF, 1e-3), 50).verdict == "contradicted",
    ),
    Fact(
        "docs/one-cart.md",
        "0.9765 at each of its searches 1–9, all accepted, only search 1 an improvement",
        lambda: (
            (run := trials(ONE).query("p == 0.001 and run == 0").set_index("index"))
            .loc[1:9, "fitness"]
            .nunique()
            == 1
            and run.loc[1:9, "accepted"].all()
            and list(run.loc[1:9, "improved"]) == [True] + [False] * 8
        ),
    ),
    Fact(
        "docs/one-cart.md",
        "every search its whole budget (`min_steps` = `max_steps`)",
        lambda: (
            settings(ONE).ddpg.min_steps == settings(ONE).ddpg.max_steps
            and (trials(ONE)["env_steps"] == settings(ONE).ddpg.max_steps).all()
        ),
    ),
    Fact(
        "docs/one-cart.md",
        "every run of both p took its 10 searches",
        lambda: (searches_per_run(ONE) == 10).all() and len(searches_per_run(ONE)) == 20,
    ),
    Fact(
        "docs/study-geometry.md",
        "and 0.9765 on each of 16 starts perturbed",
        lambda: (
            imitation_perturbed().robust_min[0] == imitation_perturbed().robust_mean[0]
            or np.isclose(imitation_perturbed().robust_std[0], 0.0, atol=1e-12)
        ),
    ),
    Fact(
        "docs/study-geometry.md",
        "(best 0.4385, the highest two-cart optimum yet",
        lambda: (
            cell("geometry-wide")["best_all"].max()
            > max(best(REF), swing_up_cells("two-cart")["best_all"].max())
        ),
    ),
    Fact(
        "docs/study-two-cart.md",
        "No cell found a policy that balances both rods, keeps one rod up, or reaches 0.9 "
        "under either aggregation",
        lambda: (
            not study("two-cart")[0][
                [
                    "first_090_all_steps",
                    "first_090_mean_steps",
                    "first_balancing_all_steps",
                    "first_balancing_mean_steps",
                    "first_rod_up_all_steps",
                    "first_rod_up_mean_steps",
                ]
            ]
            .notna()
            .any()
            .any()
        ),
    ),
    Fact(
        "docs/study-two-cart.md",
        "of the upright-start cell's best policies two spin their rods, one crashes and one "
        "stops at a track end",
        lambda: (
            behaviour_counts(cell("two-cart", "height_upright-start")["behaviour"])
            == "spinning (independent) 2, crash 1, stops at boundary 1"
        ),
    ),
    Fact(
        "docs/study-two-cart.md",
        "(14–21 env steps in the last quarter of 10 of their 12 searches",
        lambda: (
            sum(
                14 <= episode_lengths(history("two-cart", suffix, i), 3) <= 21
                for suffix in ("height", "height-product", "height_continue")
                for i in range(4)
            )
            == 10
        ),
    ),
    Fact(
        "docs/study-two-cart.md",
        "only the exploring-starts searches kept long ones (580–2000 env steps in the last "
        "quarter)",
        lambda: all(
            580 <= episode_lengths(history("two-cart", "height_explore", i), 3) <= 2000
            for i in range(4)
        ),
    ),
    Fact(
        "docs/rollout.md",
        "Even 1e-6 of start noise halves the fitness of four optima in ten",
        lambda: all(round(10 * (1 - retention(p)[0])) == 4 for p in (1e-4, 1e-3)),
    ),
    Fact(
        "docs/rollout.md",
        "| p = 1e-4 (32 optima) |",  # the stored retention at 0.01 is the trials' own
        lambda: all(
            np.isclose(
                retention(p)[-1],
                (
                    retained(REF)[accepted(REF)["p"].loc[retained(REF).index] == p]["ratio"] >= 0.5
                ).mean(),
            )
            for p in (1e-4, 1e-3)
        ),
    ),
]


# --- the tests -------------------------------------------------------------------------


@cache
def page(name: str) -> str:
    """A page with every run of whitespace as one space."""
    return " ".join((ROOT / name).read_text().split())


def filled(number: Number) -> str:
    return " ".join(number.quote.format(*number.values()).split())


@pytest.mark.parametrize("number", NUMBERS, ids=[f"{n.page}:{n.quote[:40]}" for n in NUMBERS])
def test_a_number_in_the_docs_is_what_the_committed_data_give(number):
    expected = filled(number)
    assert expected in page(number.page), f"{number.page} should say: {expected}"


@pytest.mark.parametrize("fact", FACTS, ids=[f"{f.page}:{f.quote[:40]}" for f in FACTS])
def test_a_claim_in_the_docs_holds_on_the_committed_data(fact):
    assert " ".join(fact.quote.split()) in page(fact.page), fact.quote
    assert fact.holds(), f"{fact.page}: {fact.quote}"


def test_every_page_about_stored_results_has_its_numbers_checked():
    pages = {number.page for number in NUMBERS}
    assert {
        "README.md",
        "docs/results.md",
        "docs/one-cart.md",
        "docs/study-geometry.md",
        "docs/study-two-cart.md",
        "docs/rollout.md",
    } <= pages
