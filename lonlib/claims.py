"""The paper's claims, tested on a stored experiment: evidence, numbers and a verdict each.

:func:`paper_claims` reads an experiment folder and returns one row per claim of the
paper's §IV (ids ``a`` to ``e``, the paper's words quoted in ``paper``): ``evidence`` (the
numbers, readable), ``verdict`` (:data:`REPRODUCED`, :data:`NOT_REPRODUCED` or
:data:`NOT_TESTABLE`) and numeric columns (``n``, ``statistic``, ``p_value``, ``effect``
named by ``measure``, ``ci_low``/``ci_high``). Claims about Figs. 3-5 are tested at the
paper's p = 1e-4 (:data:`PAPER_P`), or at the smallest stored p when 1e-4 is absent
(column ``p``). Every threshold is a module constant below; a claim is "not testable" when
the data cannot decide it, never "not reproduced".

Histogram claims use :func:`lonlib.peaks.detect_peaks` on the sink fitness (Fig. 4) and
call a peak *typical* when at least :data:`TYPICAL_MIN_SINKS` sinks lie within
:data:`PEAK_WINDOW_BINS` bins of it and nearer to it than to any other peak (its
*support*), so a single stray sink is no typical optimum.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import networkx as nx
import numpy as np
import pandas as pd
from scipy import stats

from lonlib.behaviour_lon import behavioural_lon
from lonlib.effect_size import compare_greater
from lonlib.lon import build_lon, mlon, sinks
from lonlib.lon_metrics import node_metrics
from lonlib.peaks import compare_with_paper, detect_peaks
from lonlib.store import p_label, read_finished_trials

REPRODUCED = "reproduced"
NOT_REPRODUCED = "not reproduced"
NOT_TESTABLE = "not testable at this scale"
VERDICTS = (REPRODUCED, NOT_REPRODUCED, NOT_TESTABLE)

PAPER_P = 1e-4
"""The p of the paper's Figs. 3-5 (claims a, b, d, e) and its better perturbation (c)."""
PAPER_P_LARGE = 1e-3
"""The paper's other perturbation strength, the one claim c says is worse."""
ALPHA = 0.05
"""Significance level of the one-sided tests of claims c and e."""
MIN_RUNS_PER_P = 5
"""Claim c needs at least this many runs at each of the two p values: 3 runs against 3
cannot reach ALPHA with the one-sided Mann-Whitney U test at all (p = 1/20 at best), 4
against 4 only when every run of one p beats every run of the other (p = 1/70); from 5
runs per p a few overlapping runs still leave room for significance (the paper ran 100)."""
MIN_SINKS = 10
"""Claims a and b need at least this many sinks (one per run) at the examined p: a
histogram of fewer values shows where single runs ended, not a distribution."""
MIN_DISTINCT_FITNESS = 3
"""Claims a and b need at least this many distinct sink fitness values (within the LON's
tolerance): fewer cannot show several typical optima, and a flat LON (every run on one
plateau, as at the quick budget) is no test of the landscape's shape."""
MULTIMODAL_MIN_PEAKS = 3
"""Claim a ("multiple distinct typical local optima"; the paper finds five) holds with at
least this many typical peaks: two would be bimodal, which the paper's wording exceeds."""
TYPICAL_MIN_SINKS = 2
"""A detected peak is a typical optimum when at least this many sinks support it: a level
that two runs ended on recurs; one sink is one run's end."""
PEAK_WINDOW_BINS = 1.5
"""Support window of a peak in histogram bins (either side of its bin centre): the peak's
bin and its neighbours, so a level split across two bins keeps all its sinks."""
MIN_OPTIMA = 10
"""Claim d needs at least this many nodes in the graph it is tested on."""
SPARSE_MAX_SHARE = 0.05
"""Claim d ("nodes are never visited by multiple inward edges") holds when at most this
share of the nodes has more than one incoming edge: "never" with room for rare merges."""
BEHAVIOUR_NODE_FEATURES = (
    "upright_share_0",
    "upright_share_1",
    "turns_0",
    "turns_1",
    "phase",
    "cart_range",
    "cart_speed",
    "end_share",
)
"""Claim d in behaviour space (pre-registered 2026-11-25, before data/reference-v2 stored a
run): a node is a class of optima whose standardised behaviour descriptors (these ``b_*``
columns of a two-cart trial, ``end_share`` = end step / nominal steps, each column z-scored
over the p's optima) lie within :data:`BEHAVIOUR_NODE_EPSILON` (Euclidean) and whose
fitness differs by at most :data:`BEHAVIOUR_NODE_FITNESS_TOLERANCE`, closed transitively
(connected components of that graph). A parameter-level LON merges two optima only when
their parameters or fitness are exactly equal, which two DDPG runs never produce, so claim
d is true there by construction; in behaviour space two runs can reach the same node."""
BEHAVIOUR_NODE_EPSILON = 0.5
"""Distance (standard deviations, Euclidean over the features) within which two optima are
one behaviour node; the report adds the share of multi-inward nodes as a curve over it."""
BEHAVIOUR_NODE_FITNESS_TOLERANCE = 0.02
"""Fitness difference (40 upright steps of 2000) within which two optima can be one node."""
GAP = (0.6, 0.7)
"""Claim e's fitness interval, half-open, as the paper states it."""
GAP_NEIGHBOURS = ((0.5, 0.6), (0.7, 0.8))
"""The equally wide intervals on either side of GAP. Where the fitness density is smooth
(locally linear) across 0.5-0.8, the middle interval holds a third of the optima in the
three, whatever the density's level; a uniform density over [0, 1] would not do as the
reference, since optima pile up at a few typical levels (claim a) and near 0."""
MIN_GAP_OPTIMA = 10
"""Claim e needs at least this many optima in 0.5-0.8: with fewer the search barely reached
the region, and an empty [0.6, 0.7) says nothing about its landscape."""
BOOTSTRAP_RESAMPLES = 2000
"""Bootstrap resamples for the confidence interval of Cliff's delta (claim c)."""
BOOTSTRAP_SEED = 0
"""Seed of the bootstrap's generator: the same experiment always gives the same interval."""
CONFIDENCE = 0.95
"""Level of the bootstrap confidence interval."""

PAPER_TEXT = {
    "a": "The problem exhibits multiple distinct typical local optima as nodes tend to "
    "cluster around specific levels of the graph rather than being evenly distributed along "
    "the z-axis. [...] The distribution of fitness values associated with these sinks "
    "reveals the presence of five peaks",
    "b": "the peaks at 0.22 and 0.32 significantly surpass the other peaks, indicating the "
    "remarkable strength of these basins of attraction compared to others",
    "c": "the smaller perturbation (1e-4) resulting in increased performance, especially at "
    "above a fitness value of 0.6",
    "d": "the landscape of local optima appears sparse. Different runs seem not converging to "
    "the same local optimum, as nodes are never visited by multiple inward edges",
    "e": "the limited occurrence of local optima between fitness values of 0.6 and 0.7 "
    "indicates a surprisingly smooth landscape beyond a fitness of 0.6",
}


@dataclass(frozen=True)
class Claim:
    """One row of the claims table (see the module docstring for the columns)."""

    claim: str
    paper: str
    verdict: str
    evidence: str
    p: float = float("nan")
    n: float = float("nan")
    statistic: float = float("nan")
    p_value: float = float("nan")
    measure: str = ""
    effect: float = float("nan")
    ci_low: float = float("nan")
    ci_high: float = float("nan")

    def __post_init__(self) -> None:
        if self.verdict not in VERDICTS:
            raise ValueError(f"verdict must be one of {VERDICTS}, got {self.verdict!r}")


@dataclass(frozen=True)
class Landscape:
    """What the claims need of one p: its LON (:func:`~lonlib.lon.build_lon`, maximised),
    the fitness of its sinks and of all its optima, and each run's best (final) fitness."""

    p: float
    graph: nx.DiGraph
    sink_fitness: np.ndarray
    optima_fitness: np.ndarray
    run_best: np.ndarray

    @property
    def labelled(self) -> bool:
        """True when some optimum carries a behaviour label (lonlib.behaviour)."""
        return any(label for _, label in self.graph.nodes(data="label", default=""))


def landscapes(trials: pd.DataFrame, tolerance: float = 1e-9) -> dict[float, Landscape]:
    """One :class:`Landscape` per stored p, in increasing p."""
    out = {}
    for p, group in trials.groupby("p", sort=True):
        graph = build_lon(group, "max", tolerance)
        fitness = dict(graph.nodes(data="fitness"))
        out[float(p)] = Landscape(
            p=float(p),
            graph=graph,
            sink_fitness=np.array([fitness[n] for n in sinks(graph)], float),
            optima_fitness=np.array(list(fitness.values()), float),
            run_best=np.array([fitness[n] for n in graph.graph["run_ends"].values()], float),
        )
    return out


def examined_p(values: list[float]) -> float | None:
    """The p the single-p claims are tested at: :data:`PAPER_P` if stored, else the
    smallest stored p (None when nothing is stored)."""
    for p in values:
        if np.isclose(p, PAPER_P, rtol=1e-9, atol=0.0):
            return p
    return min(values) if values else None


def distinct(values: np.ndarray, tolerance: float) -> int:
    """How many distinct values ``values`` holds, values within ``tolerance`` of their
    sorted neighbour counting as one (as the LON's equality chains them)."""
    if len(values) == 0:
        return 0
    return 1 + int((np.diff(np.sort(values)) > tolerance).sum())


def peak_support(values: np.ndarray, centres: np.ndarray, window: float) -> np.ndarray:
    """Per peak centre, the values nearer to it than to any other centre and at most
    ``window`` from it."""
    if len(centres) == 0:
        return np.zeros(0, int)
    distance = np.abs(np.asarray(values, float)[:, None] - np.asarray(centres, float)[None, :])
    nearest = distance.argmin(axis=1)
    near = distance[np.arange(len(nearest)), nearest] <= window
    return np.bincount(nearest[near], minlength=len(centres))


def typical_peaks(sink_fitness: np.ndarray, bins: int) -> pd.DataFrame:
    """Peaks of the sink histogram (:func:`~lonlib.peaks.detect_peaks`) with ``support``
    (sinks within :data:`PEAK_WINDOW_BINS` bins, nearest to it) and ``typical``
    (support of at least :data:`TYPICAL_MIN_SINKS`), sorted by fitness."""
    peaks = detect_peaks(sink_fitness, bins=bins).sort_values("fitness", ignore_index=True)
    window = PEAK_WINDOW_BINS / bins
    support = peak_support(sink_fitness, peaks["fitness"].to_numpy(float), window)
    return peaks.assign(support=support, typical=support >= TYPICAL_MIN_SINKS)


def _histogram_testable(land: Landscape, tolerance: float) -> str | None:
    """Why claims a and b cannot be tested at this p (None when they can)."""
    n, levels = len(land.sink_fitness), distinct(land.sink_fitness, tolerance)
    if n < MIN_SINKS:
        return f"{n} sinks at p = {p_label(land.p)}, fewer than {MIN_SINKS}"
    if levels < MIN_DISTINCT_FITNESS:
        return (
            f"{n} sinks at p = {p_label(land.p)} take only {levels} distinct fitness "
            f"value(s), fewer than {MIN_DISTINCT_FITNESS}"
        )
    return None


def _peak_list(peaks: pd.DataFrame) -> str:
    return ", ".join(
        f"{f:.2f} ({s} sinks)" for f, s in zip(peaks["fitness"], peaks["support"], strict=True)
    )


def claim_multimodal(land: Landscape, bins: int, tolerance: float) -> Claim:
    """Claim a: the sink histogram has at least :data:`MULTIMODAL_MIN_PEAKS` typical peaks."""
    base = {"claim": "a", "paper": PAPER_TEXT["a"], "p": land.p, "n": len(land.sink_fitness)}
    reason = _histogram_testable(land, tolerance)
    if reason:
        return Claim(**base, verdict=NOT_TESTABLE, evidence=reason)
    peaks = typical_peaks(land.sink_fitness, bins)
    typical = peaks[peaks["typical"]]
    verdict = REPRODUCED if len(typical) >= MULTIMODAL_MIN_PEAKS else NOT_REPRODUCED
    evidence = (
        f"{len(typical)} typical peak(s) (>= {TYPICAL_MIN_SINKS} sinks each) among "
        f"{len(peaks)} detected in the histogram of {len(land.sink_fitness)} sinks "
        f"({bins} bins): {_peak_list(typical) or 'none'}; "
        f"needed >= {MULTIMODAL_MIN_PEAKS} (paper: 5)"
    )
    return Claim(
        **base, verdict=verdict, evidence=evidence, statistic=len(typical), measure="peaks"
    )


def claim_low_basins_strongest(land: Landscape, bins: int, tolerance: float) -> Claim:
    """Claim b: with k typical sink peaks sorted by fitness, the lowest floor(k/2) (the
    paper: 0.22 and 0.32 of its five) each hold more sinks than every other typical peak.
    Incoming transitions (summed MLON in-strength of the optima nearest each peak) are
    reported beside; ``effect`` is the weakest low peak's sinks / the strongest other's."""
    base = {"claim": "b", "paper": PAPER_TEXT["b"], "p": land.p, "n": len(land.sink_fitness)}
    reason = _histogram_testable(land, tolerance)
    if reason:
        return Claim(**base, verdict=NOT_TESTABLE, evidence=reason)
    typical = typical_peaks(land.sink_fitness, bins)
    typical = typical[typical["typical"]].reset_index(drop=True)
    if len(typical) < 2:
        return Claim(
            **base,
            verdict=NOT_TESTABLE,
            evidence=f"{len(typical)} typical sink peak(s): no other basin to compare with",
        )
    centres = typical["fitness"].to_numpy(float)
    node = node_metrics(mlon(land.graph))
    nearest = np.abs(node["fitness"].to_numpy()[:, None] - centres[None, :]).argmin(axis=1)
    arrivals = np.bincount(nearest, node["in_strength"].to_numpy(), len(centres)).astype(int)
    n_low = len(typical) // 2
    support = typical["support"].to_numpy()
    low, high = support[:n_low], support[n_low:]
    verdict = REPRODUCED if low.min() > high.max() else NOT_REPRODUCED
    rows = ", ".join(
        f"{f:.2f}: {s} sinks, {a} arrivals"
        for f, s, a in zip(centres, support, arrivals, strict=True)
    )
    evidence = (
        f"low-fitness = the lowest {n_low} of {len(typical)} typical sink peaks "
        f"(<= {centres[n_low - 1]:.2f}); weakest low peak {low.min()} sinks vs strongest "
        f"other {high.max()}; per peak (arrivals = incoming transitions to the optima "
        f"nearest it): {rows}"
    )
    return Claim(
        **base,
        verdict=verdict,
        evidence=evidence,
        statistic=float(low.min()),
        measure="weakest low peak's sinks / strongest other's",
        effect=float(low.min() / high.max()),
    )


def claim_smaller_p_better(
    by_p: dict[float, Landscape], resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> Claim:
    """Claim c: each run's best fitness is higher at p = 1e-4 than at 1e-3. One-sided
    Mann-Whitney U (runs are independent; optima within a run are not), Cliff's delta with
    a seeded bootstrap interval. Reproduced when p_value < :data:`ALPHA` and the interval
    lies above 0."""
    base = {"claim": "c", "paper": PAPER_TEXT["c"]}
    stored = list(by_p)
    small = next((by_p[p] for p in stored if np.isclose(p, PAPER_P, rtol=1e-9, atol=0)), None)
    large = next((by_p[p] for p in stored if np.isclose(p, PAPER_P_LARGE, rtol=1e-9, atol=0)), None)
    if small is None or large is None:
        names = ", ".join(p_label(p) for p in stored) or "none"
        return Claim(
            **base,
            verdict=NOT_TESTABLE,
            evidence=f"needs both p = 1e-4 and p = 1e-3; stored: {names}",
        )
    x, y = small.run_best, large.run_best
    base["n"] = min(len(x), len(y))
    if len(x) < MIN_RUNS_PER_P or len(y) < MIN_RUNS_PER_P:
        return Claim(
            **base,
            verdict=NOT_TESTABLE,
            evidence=f"{len(x)} runs at p = 1e-4 and {len(y)} at 1e-3; each needs "
            f">= {MIN_RUNS_PER_P}",
        )
    if distinct(np.concatenate([x, y]), small.graph.graph["tolerance"]) < 2:
        return Claim(
            **base,
            verdict=NOT_TESTABLE,
            evidence=f"every run at both p ends at fitness {x[0]:.3g}: nothing to compare",
        )
    result = compare_greater(x, y, resamples=resamples, confidence=CONFIDENCE, seed=seed)
    better = result.p_value < ALPHA and result.ci_low > 0
    evidence = (
        f"best fitness per run, p = 1e-4 vs 1e-3: median {np.median(x):.3f} vs "
        f"{np.median(y):.3f} ({len(x)} vs {len(y)} runs); one-sided Mann-Whitney U = "
        f"{result.u:.1f}, p = {result.p_value:.3g}; Cliff's delta {result.delta:+.2f}, "
        f"{CONFIDENCE:.0%} bootstrap CI [{result.ci_low:+.2f}, {result.ci_high:+.2f}] "
        f"({resamples} resamples, seed {seed}); median difference "
        f"{result.median_difference:+.3f}"
    )
    return Claim(
        **base,
        verdict=REPRODUCED if better else NOT_REPRODUCED,
        evidence=evidence,
        statistic=result.u,
        p_value=result.p_value,
        measure="Cliff's delta",
        effect=result.delta,
        ci_low=result.ci_low,
        ci_high=result.ci_high,
    )


def claim_sparse(land: Landscape) -> Claim:
    """Claim d: at most :data:`SPARSE_MAX_SHARE` of the nodes have more than one incoming
    edge. Tested on the MLON of the behavioural LON (:mod:`lonlib.behaviour_lon`): in
    lonlib's own LON an optimum is one run's parameter vector, reached by one edge by
    construction, so only optima merged by behaviour and fitness can show runs meeting.
    Without behaviour labels the claim is not testable."""
    base = {"claim": "d", "paper": PAPER_TEXT["d"], "p": land.p}
    graph = mlon(land.graph)
    crowded = sum(1 for _, d in graph.in_degree() if d > 1)
    if not land.labelled:
        return Claim(
            **base,
            n=graph.number_of_nodes(),
            verdict=NOT_TESTABLE,
            evidence=f"no behaviour labels: on the LON {crowded} of "
            f"{graph.number_of_nodes()} optima have more than one incoming edge, but each "
            "optimum is one run's parameter vector, so runs cannot meet by construction",
        )
    graph = mlon(behavioural_lon(land.graph))
    nodes = graph.number_of_nodes()
    crowded = sum(1 for _, d in graph.in_degree() if d > 1)
    base["n"] = nodes
    if nodes < MIN_OPTIMA:
        return Claim(
            **base,
            verdict=NOT_TESTABLE,
            evidence=f"{nodes} nodes in the behavioural LON, fewer than {MIN_OPTIMA}",
        )
    share = crowded / nodes
    evidence = (
        f"{crowded} of {nodes} nodes of the behavioural LON (same label and equal fitness "
        f"merged, {land.graph.number_of_nodes()} optima) have more than one incoming edge: "
        f"{share:.1%}; sparse means <= {SPARSE_MAX_SHARE:.0%}"
    )
    return Claim(
        **base,
        verdict=REPRODUCED if share <= SPARSE_MAX_SHARE else NOT_REPRODUCED,
        evidence=evidence,
        statistic=crowded,
        measure="share of nodes with > 1 incoming edge",
        effect=share,
    )


def _count(values: np.ndarray, interval: tuple[float, float]) -> int:
    return int(((values >= interval[0]) & (values < interval[1])).sum())


def claim_gap(land: Landscape) -> Claim:
    """Claim e: fewer optima in [0.6, 0.7) than a smooth density predicts from its
    neighbours [0.5, 0.6) and [0.7, 0.8) (a third of the three; see :data:`GAP_NEIGHBOURS`).
    One-sided binomial test; ``effect`` is the gap's count / the neighbours' mean count."""
    base = {"claim": "e", "paper": PAPER_TEXT["e"], "p": land.p}
    values = land.optima_fitness
    mid = _count(values, GAP)
    lo, hi = (_count(values, interval) for interval in GAP_NEIGHBOURS)
    n = mid + lo + hi
    base["n"] = n
    counts = f"[0.5, 0.6): {lo}, [0.6, 0.7): {mid}, [0.7, 0.8): {hi} optima"
    if n < MIN_GAP_OPTIMA:
        return Claim(
            **base,
            verdict=NOT_TESTABLE,
            evidence=f"{counts}; fewer than {MIN_GAP_OPTIMA} optima in 0.5-0.8 (of {len(values)})",
        )
    test = stats.binomtest(mid, n, 1 / 3, alternative="less")
    neighbours = (lo + hi) / 2
    ratio = mid / neighbours if neighbours else float("inf")
    evidence = (
        f"{counts} ({mid / len(values):.1%} of all {len(values)} optima in [0.6, 0.7), "
        f"10% under a uniform density on [0, 1]); a smooth density puts a third of the "
        f"{n} in the middle ({n / 3:.1f}); one-sided binomial p = {test.pvalue:.3g}"
    )
    return Claim(
        **base,
        verdict=REPRODUCED if test.pvalue < ALPHA else NOT_REPRODUCED,
        evidence=evidence,
        statistic=mid,
        p_value=float(test.pvalue),
        measure="gap count / neighbours' mean",
        effect=ratio,
    )


def claims_from_trials(
    trials: pd.DataFrame,
    bins: int = 50,
    tolerance: float = 1e-9,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> pd.DataFrame:
    """The claims table of stored trials (see the module docstring), rows a to e."""
    by_p = landscapes(trials, tolerance)
    land = by_p[examined_p(list(by_p))]
    rows = [
        claim_multimodal(land, bins, tolerance),
        claim_low_basins_strongest(land, bins, tolerance),
        claim_smaller_p_better(by_p, resamples, seed),
        claim_sparse(land),
        claim_gap(land),
    ]
    return pd.DataFrame([asdict(row) for row in rows])


def peaks_beside_paper(
    trials: pd.DataFrame, bins: int = 50, tolerance: float = 1e-9
) -> pd.DataFrame:
    """At the examined p, each of the paper's peaks beside the nearest peak detected in the
    sink histogram (Fig. 4) and in the optima histogram (Fig. 5), with their distance and
    the histogram's number of values (``values``: with few, every peak is one optimum)."""
    by_p = landscapes(trials, tolerance)
    land = by_p[examined_p(list(by_p))]
    tables = [
        compare_with_paper(detect_peaks(values, bins=bins)).assign(
            p=land.p, histogram=what, values=len(values)
        )
        for what, values in (("sinks", land.sink_fitness), ("optima", land.optima_fitness))
    ]
    return pd.concat(tables, ignore_index=True)


def paper_claims(
    folder: str | Path,
    bins: int = 50,
    tolerance: float = 1e-9,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> pd.DataFrame:
    """The claims table (rows a to e) of the experiment stored in ``folder``."""
    return claims_from_trials(read_finished_trials(folder), bins, tolerance, resamples, seed)
