"""The paper's claims, tested on a stored experiment: evidence, numbers and a verdict each.

:func:`paper_claims` reads an experiment folder and returns one row per claim of the
paper's §IV (ids ``a`` to ``e``, the paper's words quoted in ``paper``): ``evidence`` (the
numbers, readable), ``verdict`` and numeric columns: ``n`` (what the test counts: sinks,
runs per p, nodes, optima), ``statistic`` (named by ``statistic_name``), ``p_value``,
``effect`` (named by ``measure``), its interval ``ci_low``/``ci_high``, ``threshold`` (the
effect's value at the border of the paper's direction) and ``direction`` (the paper's side
of it, e.g. ``> 0``). Claims about Figs. 3-5 are tested at the paper's p = 1e-4
(:data:`PAPER_P`), or at the smallest stored p when 1e-4 is absent (column ``p``). Every
threshold is a module constant below.

Verdicts say what the data can say (:data:`VERDICTS`):

* :data:`REPRODUCED`: the interval lies on the paper's side of ``threshold`` (claim c: and
  the one-sided test says so at :data:`ALPHA`; claim d, a claim of absence: the share is at
  most the threshold on at least :data:`MIN_SPARSE_NODES` nodes);
* :data:`CONTRADICTED`: the interval excludes the paper's direction (claim c: and the
  one-sided test decides against the paper at :data:`ALPHA`; claim d: the one-sided
  binomial test says the share exceeds the threshold);
* :data:`INCONCLUSIVE`: the test was computed and neither holds;
* :data:`NOT_TESTABLE`: the test could not be computed (a, b: fewer than
  :data:`MIN_SINKS` sinks, b also fewer than two typical peaks; c: p = 1e-4 or 1e-3
  missing or fewer than :data:`MIN_RUNS_PER_P` runs at one; d: no behaviour descriptors;
  e: fewer than :data:`MIN_GAP_OPTIMA` optima in 0.5-0.8).

Intervals are two-sided at :data:`CONFIDENCE` = 1 - 2 :data:`ALPHA` (90 %), so each end is
a one-sided test at ALPHA: the lower end beyond the threshold reproduces the claim at
ALPHA, the upper end short of it contradicts it at ALPHA. Per claim:

=====  =====================================  ==============  =============================
claim  effect (interval)                      threshold       paper's direction
=====  =====================================  ==============  =============================
a      typical sink peaks (bootstrap over     3 peaks         >= 3: reproduced when the
       the runs' sinks, seeded)                               lower end >= 3, contradicted
                                                              when the upper end < 3
b      weakest low basin's sinks / strongest  1 (equal        > 1: reproduced when the lower
       other's (Clopper-Pearson; the upper    strength)       end > 1, contradicted when
       end Bonferroni over the pairs)                         the upper end <= 1
c      Cliff's delta, run bests at 1e-4 over  0               > 0: reproduced when the lower
       1e-3 (bootstrap over runs, seeded)                     end > 0, contradicted when
                                                              the upper end <= 0
d      share of behaviour nodes with > 1      0.05            <= 0.05: reproduced when the
       distinct in-edge (Clopper-Pearson)                     share is, contradicted when
                                                              the lower end > 0.05
e      optima in [0.6, 0.7) / the mean of     1 (smooth       < 1: reproduced when the upper
       its neighbours (Clopper-Pearson)       density)        end < 1, contradicted when
                                                              the lower end >= 1
=====  =====================================  ==============  =============================

Histogram claims use :func:`lonlib.analysis.peaks.detect_peaks` on the sink fitness (Fig. 4) and
call a peak *typical* when at least :data:`TYPICAL_MIN_SINKS` sinks lie within
:data:`PEAK_WINDOW_BINS` bins of it and nearer to it than to any other peak (its
*support*), so a single stray sink is no typical optimum.

The smallest effects of interest (``*_SOI*``), stated before the data, are what
:func:`lonlib.analysis.claims_power.power_table` sizes an experiment for.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd
from scipy import stats
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks

from lonlib.analysis.effect_size import compare_greater
from lonlib.analysis.landscape import Landscape, landscapes
from lonlib.analysis.peaks import compare_with_paper, detect_peaks
from lonlib.lon.behaviour import behavioural_lon
from lonlib.lon.behaviour_space import behaviour_node_curve, behaviour_nodes
from lonlib.lon.graphs import mlon
from lonlib.lon.metrics import node_metrics
from lonlib.storage.trials import read_finished_trials
from lonlib.util.labels import p_label

REPRODUCED = "reproduced"
CONTRADICTED = "contradicted"
INCONCLUSIVE = "inconclusive at this n"
NOT_TESTABLE = "not testable at this scale"
VERDICTS = (REPRODUCED, CONTRADICTED, INCONCLUSIVE, NOT_TESTABLE)

PAPER_P = 1e-4
"""The p of the paper's Figs. 3-5 (claims a, b, d, e) and its better perturbation (c)."""
PAPER_P_LARGE = 1e-3
"""The paper's other perturbation strength, the one claim c says is worse."""
ALPHA = 0.05
"""One-sided significance level of every verdict (either way) and of the power table."""
CONFIDENCE = 1 - 2 * ALPHA
"""Level of the two-sided intervals (90 %): each end is a one-sided test at ALPHA."""
POWER = 0.80
"""The power the power table sizes an experiment for."""
MIN_RUNS_PER_P = 4
"""Claim c needs at least this many runs at each of the two p values: at 3 against 3 the
one-sided Mann-Whitney U test cannot reach ALPHA whatever the data (p >= 1/20), so no
verdict but *inconclusive* could come out; at 4 against 4 it can (p = 1/70 when every run
of one p beats every run of the other)."""
MIN_SINKS = 10
"""Claims a and b need at least this many sinks (one per run) at the examined p: a
histogram of fewer values shows where single runs ended, not a distribution."""
MULTIMODAL_MIN_PEAKS = 3
"""Claim a ("multiple distinct typical local optima"; the paper finds five) holds with at
least this many typical peaks: two would be bimodal, which the paper's wording exceeds."""
TYPICAL_MIN_SINKS = 2
"""A detected peak is a typical optimum when at least this many sinks support it: a level
that two runs ended on recurs; one sink is one run's end."""
PEAK_WINDOW_BINS = 1.5
"""Support window of a peak in histogram bins (either side of its bin centre): the peak's
bin and its neighbours, so a level split across two bins keeps all its sinks."""
MULTIMODAL_SOI_SHARES = (0.45, 0.45, 0.10)
"""Claim a's smallest effect of interest: sinks on three well separated levels, the
weakest attracting one run in ten. A level fewer runs end at is no *typical* optimum worth
the name, and three is the fewest the claim (five in the paper) still describes."""
LOW_BASINS_SOI_WEIGHTS = (2, 2, 1, 1, 1)
"""Claim b's smallest effect of interest: the paper's five sink peaks, each of the two low
ones attracting twice the sinks of each other one (a ratio of 2 in claim b's decisive
pair): "significantly surpass" and "remarkable strength" describe no smaller difference."""
SMALLER_P_SOI_DELTA = 0.47
"""Claim c's smallest effect of interest: Cliff's delta 0.47, a *large* effect by Romano et
al. (2006; |delta| >= 0.474), i.e. a run at 1e-4 beats a run at 1e-3 about three times in
four: the paper reads the difference off a boxplot (Fig. 2), which shows no smaller one."""
SPARSE_MAX_SHARE = 0.05
"""Claim d ("nodes are never visited by multiple inward edges") holds when at most this
share of the nodes has more than one incoming edge: "never" with room for rare merges."""
MIN_SPARSE_NODES = 10
"""Claim d is reproduced (share <= :data:`SPARSE_MAX_SHARE`) only on at least this many
behaviour nodes: 0 multi-inward nodes of a handful says little (its interval is wide), so
fewer leave it *inconclusive*."""
SPARSE_SOI_SHARE = 0.15
"""Claim d's smallest effect of interest (against the paper): one behaviour node in seven
entered from two or more others, three times the share "never" allows; a landscape where
runs meet that often is no longer sparse in the paper's sense."""
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
"""Claim d in behaviour space (pre-registered 2026-11-25, before today's data/reference stored a
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
BEHAVIOUR_NODE_CURVE = tuple(round(0.1 * k, 1) for k in range(1, 21))
"""The epsilons of claim d's curve (0.1 to 2.0 standard deviations)."""
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
GAP_SOI_RATIO = 0.5
"""Claim e's smallest effect of interest: [0.6, 0.7) holds half the optima its neighbours
hold on average (a fifth of the three intervals' optima instead of a third); a smaller dip
is no "limited occurrence"."""
BOOTSTRAP_RESAMPLES = 2000
"""Bootstrap resamples for the intervals of claims a (typical peaks) and c (Cliff's delta)."""
BOOTSTRAP_SEED = 0
"""Seed of the bootstrap's generator: the same experiment always gives the same interval."""

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
    statistic_name: str = ""
    p_value: float = float("nan")
    measure: str = ""
    effect: float = float("nan")
    ci_low: float = float("nan")
    ci_high: float = float("nan")
    threshold: float = float("nan")
    direction: str = ""

    def __post_init__(self) -> None:
        if self.verdict not in VERDICTS:
            raise ValueError(f"verdict must be one of {VERDICTS}, got {self.verdict!r}")


def examined_p(values: list[float]) -> float | None:
    """The p the single-p claims are tested at: :data:`PAPER_P` if stored, else the
    smallest stored p (None when nothing is stored)."""
    for p in values:
        if np.isclose(p, PAPER_P, rtol=1e-9, atol=0.0):
            return p
    return min(values) if values else None


def clopper_pearson(k, n, confidence: float = CONFIDENCE):
    """The exact (Clopper-Pearson) two-sided interval of a binomial proportion: ``k``
    successes of ``n`` (arrays broadcast). Each end inverts the one-sided exact binomial
    test at (1 - confidence) / 2: the upper end is below p0 exactly when the test of
    "share < p0" gives p < (1 - confidence) / 2."""
    k, n = np.asarray(k, float), np.asarray(n, float)
    tail = (1 - confidence) / 2
    with np.errstate(all="ignore"):
        low = np.where(k > 0, stats.beta.ppf(tail, k, n - k + 1), 0.0)
        high = np.where(k < n, stats.beta.ppf(1 - tail, k + 1, n - k), 1.0)
    if low.ndim == 0:
        return float(low), float(high)
    return low, high


def _ratio(share: float) -> float:
    """``share / (1 - share)``: a share of a pair as the ratio of its two counts."""
    return share / (1 - share) if share < 1 else float("inf")


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
    """Peaks of the sink histogram (:func:`~lonlib.analysis.peaks.detect_peaks`) with ``support``
    (sinks within :data:`PEAK_WINDOW_BINS` bins, nearest to it) and ``typical``
    (support of at least :data:`TYPICAL_MIN_SINKS`), sorted by fitness."""
    peaks = detect_peaks(sink_fitness, bins=bins).sort_values("fitness", ignore_index=True)
    window = PEAK_WINDOW_BINS / bins
    support = peak_support(sink_fitness, peaks["fitness"].to_numpy(float), window)
    return peaks.assign(support=support, typical=support >= TYPICAL_MIN_SINKS)


def bootstrap_typical_peaks(
    sink_fitness: np.ndarray, bins: int, resamples: int, seed: int
) -> np.ndarray:
    """The number of typical peaks (:func:`typical_peaks`) of each of ``resamples``
    bootstrap resamples of the sinks (with replacement, the generator seeded with
    ``seed``). Computed on the resamples' counts per distinct value (a multinomial draw),
    with :func:`~lonlib.analysis.peaks.detect_peaks`'s defaults (Gaussian smoothing of 1 bin,
    prominence 5 % of the tallest smoothed bin) and the support rule of
    :func:`peak_support`: the same count as :func:`typical_peaks` on each resample."""
    values = np.asarray(sink_fitness, float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return np.zeros(resamples, int)
    distinct, counts = np.unique(values, return_counts=True)
    draws = np.random.default_rng(seed).multinomial(values.size, counts / values.size, resamples)
    one_hot = np.array([np.histogram([v], bins=bins, range=(0.0, 1.0))[0] for v in distinct])
    histograms = draws @ one_hot
    edges = np.linspace(0.0, 1.0, bins + 1)
    centres = 0.5 * (edges[:-1] + edges[1:])
    smooth = gaussian_filter1d(histograms.astype(float), 1.0, axis=1)
    window = PEAK_WINDOW_BINS / bins
    out = np.zeros(resamples, int)
    for b in range(resamples):
        if not histograms[b].any():
            continue
        padded = np.concatenate([[0.0], smooth[b], [0.0]])
        index, _ = find_peaks(padded, prominence=max(0.05 * smooth[b].max(), 1e-9))
        peak = centres[index - 1]
        distance = np.abs(distinct[:, None] - peak[None, :])
        nearest = distance.argmin(axis=1)
        near = distance[np.arange(distinct.size), nearest] <= window
        support = np.bincount(nearest[near], weights=draws[b][near], minlength=peak.size)
        out[b] = int((support >= TYPICAL_MIN_SINKS).sum())
    return out


def _peak_list(peaks: pd.DataFrame) -> str:
    return ", ".join(
        f"{f:.2f} ({s} sinks)" for f, s in zip(peaks["fitness"], peaks["support"], strict=True)
    )


def _too_few_sinks(land: Landscape) -> str | None:
    """Why claims a and b cannot be tested at this p (None when they can)."""
    n = len(land.sink_fitness)
    if n < MIN_SINKS:
        return f"{n} sinks at p = {p_label(land.p)}, fewer than {MIN_SINKS}"
    return None


def _verdict(reproduced: bool, contradicted: bool) -> str:
    """The verdict of a computed test (the rules are each claim's)."""
    return REPRODUCED if reproduced else CONTRADICTED if contradicted else INCONCLUSIVE


def claim_multimodal(
    land: Landscape, bins: int, resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> Claim:
    """Claim a: the sink histogram has at least :data:`MULTIMODAL_MIN_PEAKS` typical peaks.
    Interval: the seeded percentile bootstrap of the typical-peak count over the runs'
    sinks (one per run, independent), at :data:`CONFIDENCE`. Reproduced when its lower end
    is at least 3 (fewer than 3 in at most ALPHA of the resamples), contradicted when its
    upper end is below 3 (3 or more in at most ALPHA of them). A resample repeats sinks, so
    a stray sink drawn twice can count as typical: the upper end leans high, which makes
    *contradicted* the harder verdict."""
    base = {"claim": "a", "paper": PAPER_TEXT["a"], "p": land.p, "n": len(land.sink_fitness)}
    reason = _too_few_sinks(land)
    if reason:
        return Claim(**base, verdict=NOT_TESTABLE, evidence=reason)
    peaks = typical_peaks(land.sink_fitness, bins)
    typical = peaks[peaks["typical"]]
    counts = bootstrap_typical_peaks(land.sink_fitness, bins, resamples, seed)
    tail = (1 - CONFIDENCE) / 2
    low, high = (float(q) for q in np.quantile(counts, [tail, 1 - tail], method="inverted_cdf"))
    need = MULTIMODAL_MIN_PEAKS
    evidence = (
        f"{len(typical)} typical peak(s) (>= {TYPICAL_MIN_SINKS} sinks each) among "
        f"{len(peaks)} detected in the histogram of {len(land.sink_fitness)} sinks "
        f"({bins} bins): {_peak_list(typical) or 'none'}; {CONFIDENCE:.0%} bootstrap interval "
        f"over the runs' sinks [{low:.0f}, {high:.0f}] ({resamples} resamples, seed {seed}); "
        f"the paper's direction: >= {need} (it found 5)"
    )
    return Claim(
        **base,
        verdict=_verdict(low >= need, high < need),
        evidence=evidence,
        statistic=len(typical),
        statistic_name="typical peaks",
        measure="typical peaks",
        effect=len(typical),
        ci_low=low,
        ci_high=high,
        threshold=need,
        direction=f">= {need}",
    )


def claim_low_basins_strongest(land: Landscape, bins: int) -> Claim:
    """Claim b: with k typical sink peaks sorted by fitness, the lowest floor(k/2) (the
    paper: 0.22 and 0.32 of its five) each hold more sinks than every other typical peak.
    The decisive pair is the weakest low peak against the strongest other: it has the
    lowest Clopper-Pearson bounds of every low x other pair (the bounds of a pair's share
    rise with the low peak's sinks and fall with the other's). ``effect`` is the pair's
    ratio of sinks (1: equal strength), its interval the Clopper-Pearson interval of the
    weak one's share, as a ratio: the lower end at one-sided ALPHA (every pair must pass,
    an intersection-union test needs no adjustment), the upper end Bonferroni-adjusted for
    the pairs (one failing pair is enough, so each tail is ALPHA / pairs). Reproduced when
    the lower end is above 1, contradicted when the upper end is at most 1; ``p_value`` is
    the one-sided exact binomial test of "weak low > strong other". Incoming transitions
    (summed MLON in-strength of the optima nearest each peak) are reported beside."""
    base = {"claim": "b", "paper": PAPER_TEXT["b"], "p": land.p, "n": len(land.sink_fitness)}
    reason = _too_few_sinks(land)
    if reason:
        return Claim(**base, verdict=NOT_TESTABLE, evidence=reason)
    typical = typical_peaks(land.sink_fitness, bins)
    typical = typical[typical["typical"]].reset_index(drop=True)
    if len(typical) < 2:
        return Claim(
            **base,
            verdict=NOT_TESTABLE,
            evidence=f"{len(typical)} typical sink peak(s): no pair of basins to compare "
            "(claim a tests how many there are)",
        )
    centres = typical["fitness"].to_numpy(float)
    node = node_metrics(mlon(land.graph))
    nearest = np.abs(node["fitness"].to_numpy()[:, None] - centres[None, :]).argmin(axis=1)
    arrivals = np.bincount(nearest, node["in_strength"].to_numpy(), len(centres)).astype(int)
    n_low = len(typical) // 2
    support = typical["support"].to_numpy()
    weak, strong = int(support[:n_low].min()), int(support[n_low:].max())
    pairs = n_low * (len(typical) - n_low)
    share_low, _ = clopper_pearson(weak, weak + strong, CONFIDENCE)
    _, share_high = clopper_pearson(weak, weak + strong, 1 - 2 * ALPHA / pairs)
    low, high = _ratio(share_low), _ratio(share_high)
    p_value = stats.binomtest(weak, weak + strong, 0.5, alternative="greater").pvalue
    rows = ", ".join(
        f"{f:.2f}: {s} sinks, {a} arrivals"
        for f, s, a in zip(centres, support, arrivals, strict=True)
    )
    evidence = (
        f"low-fitness = the lowest {n_low} of {len(typical)} typical sink peaks "
        f"(<= {centres[n_low - 1]:.2f}); weakest low peak {weak} sinks vs strongest other "
        f"{strong}: ratio {weak / strong:.2f}, interval [{low:.2f}, "
        f"{high:.2f}] (Clopper-Pearson; upper end Bonferroni-adjusted for {pairs} pair(s)); "
        f"the paper's direction: > 1; per peak (arrivals = incoming transitions to the "
        f"optima nearest it): {rows}"
    )
    return Claim(
        **base,
        verdict=_verdict(share_low > 0.5, share_high <= 0.5),
        evidence=evidence,
        statistic=weak,
        statistic_name="weakest low peak's sinks",
        p_value=float(p_value),
        measure="weakest low peak's sinks / strongest other's",
        effect=weak / strong,
        ci_low=low,
        ci_high=high,
        threshold=1.0,
        direction="> 1",
    )


def claim_smaller_p_better(
    by_p: dict[float, Landscape], resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> Claim:
    """Claim c: each run's best fitness is higher at p = 1e-4 than at 1e-3. One-sided
    Mann-Whitney U (runs are independent; optima within a run are not), Cliff's delta with
    a seeded percentile bootstrap interval at :data:`CONFIDENCE`. Reproduced when the test
    of "1e-4 greater" gives p < :data:`ALPHA` and the interval lies above 0; contradicted
    when the test of "1e-4 less" gives p < ALPHA and the interval's upper end is at most 0
    (it excludes the paper's direction); else inconclusive."""
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
    result = compare_greater(x, y, resamples=resamples, confidence=CONFIDENCE, seed=seed)
    reverse = float(stats.mannwhitneyu(x, y, alternative="less").pvalue)
    better = result.p_value < ALPHA and result.ci_low > 0
    worse = reverse < ALPHA and result.ci_high <= 0
    evidence = (
        f"each run's final incumbent, p = 1e-4 vs 1e-3: median fitness {np.median(x):.3f} vs "
        f"{np.median(y):.3f} ({len(x)} vs {len(y)} runs); one-sided Mann-Whitney U = "
        f"{result.u:.1f}, p = {result.p_value:.3g} (1e-4 greater), {reverse:.3g} (1e-4 less); "
        f"Cliff's delta {result.delta:+.2f}, {CONFIDENCE:.0%} bootstrap CI "
        f"[{result.ci_low:+.2f}, {result.ci_high:+.2f}] ({resamples} resamples, seed {seed}); "
        f"median difference {result.median_difference:+.3f}; the paper's direction: > 0"
    )
    return Claim(
        **base,
        verdict=_verdict(better, worse),
        evidence=evidence,
        statistic=result.u,
        statistic_name="Mann-Whitney U",
        p_value=result.p_value,
        measure="Cliff's delta",
        effect=result.delta,
        ci_low=result.ci_low,
        ci_high=result.ci_high,
        threshold=0.0,
        direction="> 0",
    )


def _label_level(land: Landscape) -> str:
    """Claim d's old measure, reported beside: multi-inward nodes of the label-level
    behavioural LON (same label and equal fitness merged; :mod:`lonlib.lon.behaviour`)."""
    if not land.labelled:
        return "no behaviour labels for the label-level LON"
    graph = mlon(behavioural_lon(land.graph))
    crowded = sum(1 for _, d in graph.in_degree() if d > 1)
    return (
        f"label level (same label and equal fitness merged): {crowded} of "
        f"{graph.number_of_nodes()} nodes"
    )


def claim_sparse(land: Landscape) -> Claim:
    """Claim d in behaviour space (:mod:`lonlib.lon.behaviour_space`, the pre-registered
    :data:`BEHAVIOUR_NODE_FEATURES`, :data:`BEHAVIOUR_NODE_EPSILON` and
    :data:`BEHAVIOUR_NODE_FITNESS_TOLERANCE`): the share of behaviour nodes entered by
    edges from more than one other node. Reproduced when it is at most
    :data:`SPARSE_MAX_SHARE` on at least :data:`MIN_SPARSE_NODES` nodes of which one at
    least holds two optima or more (with every optimum a node of its own, each node has one
    parent at most and the test could not fail: the same defect as the parameter-level LON;
    this condition was added after the reference's first analysis showed it); contradicted when
    the one-sided exact binomial test of "share > SPARSE_MAX_SHARE" (nodes as trials) gives
    p < ALPHA, i.e. the Clopper-Pearson interval's lower end exceeds it; else inconclusive.
    Not testable without behaviour descriptors. In the parameter-level LON every optimum
    is its own node with one in-edge at most (its parent), so the claim holds there by
    construction; the label-level count is reported beside."""
    base = {"claim": "d", "paper": PAPER_TEXT["d"], "p": land.p}
    result = behaviour_nodes(
        land.trials,
        BEHAVIOUR_NODE_FEATURES,
        BEHAVIOUR_NODE_EPSILON,
        BEHAVIOUR_NODE_FITNESS_TOLERANCE,
    )
    if not result.described:
        return Claim(
            **base,
            n=result.optima,
            verdict=NOT_TESTABLE,
            evidence=f"no behaviour descriptors (b_* columns) for the {result.optima} optima; "
            f"in the parameter-level LON each optimum is its own node, entered once at most "
            f"by construction; {_label_level(land)}",
        )
    nodes, crowded = result.nodes, result.multi_inward
    share = crowded / nodes
    low, high = clopper_pearson(crowded, nodes)
    p_value = float(stats.binomtest(crowded, nodes, SPARSE_MAX_SHARE, "greater").pvalue)
    evidence = (
        f"at epsilon {result.epsilon:g} over {len(result.features)} standardised features "
        f"and fitness within {result.fitness_tolerance:g}: {result.optima} accepted optima "
        f"({result.described} described) form {nodes} behaviour nodes; of "
        f"{result.transitions} accepted transitions {result.self_returns} stay inside a "
        f"node, the rest are {result.edges} edges; {crowded} nodes are entered from more "
        f"than one other node: {share:.1%}, {CONFIDENCE:.0%} Clopper-Pearson "
        f"[{low:.1%}, {high:.1%}]; one-sided binomial test of more than "
        f"{SPARSE_MAX_SHARE:.0%}: p = {p_value:.3g}; sparse means <= {SPARSE_MAX_SHARE:.0%} "
        f"(on >= {MIN_SPARSE_NODES} nodes); {_label_level(land)}"
    )
    merged = nodes < result.optima
    if not merged:
        evidence += (
            "; no two optima share a node at this epsilon, so no node can be entered from two "
            "others and the test cannot fail: inconclusive until nodes merge (more optima, "
            "or a coarser epsilon: claim d's curve)"
        )
    reproduced = share <= SPARSE_MAX_SHARE and nodes >= MIN_SPARSE_NODES and merged
    return Claim(
        **base,
        n=nodes,
        verdict=_verdict(reproduced, low > SPARSE_MAX_SHARE),
        evidence=evidence,
        statistic=crowded,
        statistic_name="multi-inward nodes",
        p_value=p_value,
        measure="share of nodes with > 1 distinct in-edge",
        effect=share,
        ci_low=low,
        ci_high=high,
        threshold=SPARSE_MAX_SHARE,
        direction=f"<= {SPARSE_MAX_SHARE:g}",
    )


def claim_d_curve(trials: pd.DataFrame, epsilons=BEHAVIOUR_NODE_CURVE) -> pd.DataFrame:
    """Claim d's share of multi-inward behaviour nodes per p over ``epsilon``
    (:func:`lonlib.lon.behaviour_space.behaviour_node_curve` with the pre-registered features
    and fitness tolerance) with its Clopper-Pearson interval at :data:`CONFIDENCE`
    (``ci_low``, ``ci_high``); empty without behaviour descriptors."""
    curve = behaviour_node_curve(
        trials, BEHAVIOUR_NODE_FEATURES, epsilons, BEHAVIOUR_NODE_FITNESS_TOLERANCE
    )
    low, high = clopper_pearson(curve["multi_inward"].to_numpy(), curve["nodes"].to_numpy())
    return curve.assign(ci_low=low, ci_high=high)


def _count(values: np.ndarray, interval: tuple[float, float]) -> int:
    return int(((values >= interval[0]) & (values < interval[1])).sum())


def claim_gap(land: Landscape) -> Claim:
    """Claim e: fewer optima in [0.6, 0.7) than a smooth density predicts from its
    neighbours [0.5, 0.6) and [0.7, 0.8) (a third of the three; see :data:`GAP_NEIGHBOURS`).
    ``effect``: the gap's count / the neighbours' mean count (1: smooth); its interval is the
    Clopper-Pearson interval of the gap's share of the three, as that ratio. Reproduced when
    the upper end is below 1 (the one-sided exact binomial test of "share < 1/3" gives
    p < ALPHA), contradicted when the lower end is at least 1; else inconclusive."""
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
    share_low, share_high = clopper_pearson(mid, n)
    low, high = 2 * _ratio(share_low), 2 * _ratio(share_high)
    evidence = (
        f"{counts} ({mid / len(values):.1%} of all {len(values)} optima in [0.6, 0.7), "
        f"10% under a uniform density on [0, 1]); a smooth density puts a third of the "
        f"{n} in the middle ({n / 3:.1f}); gap / neighbours' mean {2 * _ratio(mid / n):.2f}, "
        f"{CONFIDENCE:.0%} Clopper-Pearson [{low:.2f}, {high:.2f}]; one-sided binomial "
        f"p = {test.pvalue:.3g}; the paper's direction: < 1"
    )
    return Claim(
        **base,
        verdict=_verdict(share_high < 1 / 3, share_low >= 1 / 3),
        evidence=evidence,
        statistic=mid,
        statistic_name="optima in [0.6, 0.7)",
        p_value=float(test.pvalue),
        measure="gap count / neighbours' mean",
        effect=2 * _ratio(mid / n),
        ci_low=low,
        ci_high=high,
        threshold=1.0,
        direction="< 1",
    )


def claims_from_trials(
    trials: pd.DataFrame,
    bins: int = 50,
    fitness_tolerance: float = 1e-9,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> pd.DataFrame:
    """The claims table of stored trials (see the module docstring), rows a to e."""
    return claims_of_landscapes(landscapes(trials, fitness_tolerance), bins, resamples, seed)


def claims_of_landscapes(
    by_p: dict[float, Landscape],
    bins: int = 50,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> pd.DataFrame:
    """:func:`claims_from_trials` of an experiment's landscapes (one per p, in increasing p:
    :func:`~lonlib.analysis.landscape.landscapes`, or a loaded experiment's)."""
    land = by_p[examined_p(list(by_p))]
    rows = [
        claim_multimodal(land, bins, resamples, seed),
        claim_low_basins_strongest(land, bins),
        claim_smaller_p_better(by_p, resamples, seed),
        claim_sparse(land),
        claim_gap(land),
    ]
    return pd.DataFrame([asdict(row) for row in rows])


def peaks_beside_paper(
    trials: pd.DataFrame, bins: int = 50, fitness_tolerance: float = 1e-9
) -> pd.DataFrame:
    """At the examined p, each of the paper's peaks beside the nearest peak detected in the
    sink histogram (Fig. 4) and in the optima histogram (Fig. 5), with their distance and
    the histogram's number of values (``values``: with few, every peak is one optimum)."""
    return peaks_of_landscapes(landscapes(trials, fitness_tolerance), bins)


def peaks_of_landscapes(by_p: dict[float, Landscape], bins: int = 50) -> pd.DataFrame:
    """:func:`peaks_beside_paper` of an experiment's landscapes (one per p)."""
    land = by_p[examined_p(list(by_p))]
    tables = [
        compare_with_paper(detect_peaks(values, bins=bins)).assign(
            p=land.p, histogram=what, values=len(values)
        )
        for what, values in (("sinks", land.sink_fitness), ("optima", land.optima_fitness))
    ]
    return pd.concat(tables, ignore_index=True)


def paper_claims(
    folder,
    bins: int = 50,
    fitness_tolerance: float = 1e-9,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> pd.DataFrame:
    """The claims table (rows a to e) of the experiment stored in ``folder``."""
    return claims_from_trials(
        read_finished_trials(folder), bins, fitness_tolerance, resamples, seed
    )
