"""The paper's figures (2-5), the 3-D LON (PNG and interactive HTML) and a sensitivity view
(the calibration figure is :func:`lonlib.calibration.report.calibration_figure`).

Every function returns a figure (matplotlib, or plotly for the interactive LON) and leaves
saving to the caller (:func:`save_png` / :func:`png_bytes` write byte-stable PNGs), except
:func:`lon_3d_html` which writes a self-contained file (plotly.js embedded, opens offline in
a browser). The statistical figures are drawn with seaborn under one theme
(:func:`lonlib.util.figures.themed`); behaviour labels keep one colour each in every figure,
and the marks that are not behaviours (the paper's peaks, detected peaks, a run's best) are
drawn in black, which no label uses.
"""

from __future__ import annotations

import random
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import networkx as nx
import numpy as np
import pandas as pd
import seaborn as sns
from matplotlib import MatplotlibDeprecationWarning
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator

from lonlib.analysis.peaks import PAPER_PEAKS, detect_peaks
from lonlib.lon.io import to_igraph
from lonlib.task.behaviour import LABELS
from lonlib.util.figures import themed
from lonlib.util.labels import p_label

GREY, RED = "#8a8a8a", "#d62728"
# Marks that are not behaviours (the paper's peaks, detected peaks, a run's best): no label's.
INK = "#000000"
# One colour per behaviour label (lonlib.task.behaviour.LABELS order), colour-blind friendly.
LABEL_COLOURS = dict(
    zip(
        LABELS,
        (
            "#d62728",
            "#ff7f0e",
            "#1f77b4",
            "#17becf",
            "#9467bd",
            "#2ca02c",
            "#bcbd22",
            "#8c564b",
            "#e377c2",
            "#7f7f7f",
        ),
        strict=True,
    )
)


def ordered_labels(labels) -> list[str]:
    """The distinct labels present, in :data:`lonlib.task.behaviour.LABELS` order, unknown last."""
    present = {str(x) for x in labels if x}
    return [n for n in LABEL_COLOURS if n in present] + sorted(present - set(LABEL_COLOURS))


def label_colour(label: str) -> str:
    """The colour of a behaviour label in every figure (grey for an unknown one)."""
    return LABEL_COLOURS.get(label, GREY)


@contextmanager
def _fixed_jitter(seed: int = 0) -> Iterator[None]:
    """seaborn draws strip-plot jitter from numpy's global generator: seed it for the block
    (the same data give the same figure, byte for byte) and restore its state after."""
    state = np.random.get_state()  # noqa: NPY002 (seaborn reads the legacy global state)
    np.random.seed(seed)  # noqa: NPY002
    try:
        yield
    finally:
        np.random.set_state(state)  # noqa: NPY002


def _labels(graph: nx.DiGraph) -> dict[str, str] | None:
    """Node -> behaviour label, or None when the graph's nodes carry no labels."""
    labels = {n: d.get("label") for n, d in graph.nodes(data=True)}
    return labels if any(labels.values()) else None


def _count(optima: int, runs: int) -> str:
    return f"{optima} optima, {runs} run{'s' if runs != 1 else ''}"


def optima_boxplot(trials: pd.DataFrame) -> plt.Figure:
    """Fig. 2: fitness of the accepted local optima, one box per perturbation strength, every
    optimum a point, each run's best marked (claim c compares them), n under each box."""
    accepted = trials[trials["accepted"]].reset_index(drop=True)  # idxmax needs unique labels
    ps = sorted(accepted["p"].unique(), reverse=True)
    order = [p_label(p) for p in ps]
    accepted["p_label"] = [p_label(p) for p in accepted["p"]]
    bests = accepted.loc[accepted.groupby(["p", "run"])["fitness"].idxmax()]
    with themed(), _fixed_jitter():
        fig, ax = plt.subplots(figsize=(5.5, 4.2))
        common = {"data": accepted, "x": "p_label", "y": "fitness", "order": order, "ax": ax}
        with warnings.catch_warnings():  # seaborn 0.13 passes matplotlib 3.11 a deprecated `vert`
            warnings.filterwarnings("ignore", "vert: bool", MatplotlibDeprecationWarning)
            sns.boxplot(
                **common, color="#e3e3e3", width=0.55, showfliers=False, linecolor="#4d4d4d"
            )
        sns.stripplot(**common, color=GREY, size=3.5, jitter=0.12, alpha=0.8)
        sns.stripplot(
            data=bests, x="p_label", y="fitness", order=order, ax=ax, jitter=False,
            marker="D", size=6, color="white", edgecolor=INK, linewidth=1.2,
        )  # fmt: skip
        counts = {
            p_label(p): (len(group), group["run"].nunique()) for p, group in accepted.groupby("p")
        }
        ax.set_xticks(
            range(len(order)),
            [f"{label}\nn = {_count(*counts[label])}" for label in order],
        )
        ax.set_xlabel("perturbation strength p")
        ax.set_ylabel("local optimum fitness")
        ax.set_title("Fitness of sampled local optima")
        ax.legend(
            handles=[
                Line2D([], [], ls="", marker="o", color=GREY, label="accepted optimum"),
                Line2D(
                    [], [], ls="", marker="D", markerfacecolor="white", markeredgecolor=INK,
                    label="a run's best",
                ),
            ],
            fontsize=8,
            loc="best",
        )  # fmt: skip
        fig.tight_layout()
    return fig


def layout_2d(graph: nx.DiGraph, seed: int = 0) -> dict[str, tuple[float, float]]:
    """Fruchterman-Reingold positions in the plane (igraph), reproducible through ``seed``."""
    if graph.number_of_nodes() == 0:
        return {}
    ig_graph = to_igraph(graph)
    random.seed(seed)  # igraph layouts draw from Python's random
    coords = ig_graph.layout_fruchterman_reingold(niter=500)
    return {name: tuple(xy) for name, xy in zip(ig_graph.vs["_nx_name"], coords, strict=True)}


def _node_roles(graph: nx.DiGraph) -> dict[str, list[str]]:
    """Partition nodes by how they are drawn: colour marks the best, size marks a start."""
    roles: dict[str, list[str]] = {"other": [], "start": [], "best": [], "best start": []}
    for name, data in graph.nodes(data=True):
        best, start = bool(data.get("best")), bool(data.get("start"))
        role = {
            (True, True): "best start",
            (True, False): "best",
            (False, True): "start",
            (False, False): "other",
        }[best, start]
        roles[role].append(name)
    return roles


NODE_STYLE = {  # role -> (colour, matplotlib size, plotly size, legend label)
    "other": (GREY, 30, 5, "local optimum"),
    "start": (GREY, 8, 2.5, "start node"),
    "best": (RED, 60, 9, "best optimum"),
    "best start": (RED, 14, 4, "best optimum (a start node)"),
}


def lon_3d(graph: nx.DiGraph, seed: int = 0, title: str = "3-D LON") -> plt.Figure:
    """Fig. 3: LON in 3-D, layout in the plane and z = fitness. Grey nodes, the best node
    red, start nodes small; an edge darkens towards the optimum it leads to. When the nodes
    carry behaviour labels, the colour is the label's (the best node keeps its size and is
    outlined). The legend says all of this (:func:`lon_legend`)."""
    pos = layout_2d(graph, seed)
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    for u, v in graph.edges:
        start = np.array([*pos[u], graph.nodes[u]["fitness"]])
        end = np.array([*pos[v], graph.nodes[v]["fitness"]])
        head = start + 0.65 * (end - start)
        ax.plot(*np.stack([start, head]).T, color="#c8c8c8", linewidth=0.8)
        ax.plot(*np.stack([head, end]).T, color="#505050", linewidth=1.6)
    labels = _labels(graph)
    for role, names in _node_roles(graph).items():
        if not names:
            continue
        color, size, _, _ = NODE_STYLE[role]
        xyz = np.array([(*pos[n], graph.nodes[n]["fitness"]) for n in names])
        if labels is None:
            ax.scatter(*xyz.T, c=color, s=size, depthshade=False)
        else:
            colours = [label_colour(labels[n]) for n in names]
            ax.scatter(
                *xyz.T,
                c=colours,
                s=size,
                depthshade=False,
                edgecolors="black",
                linewidths=0.8 if "best" in role else 0.0,
            )
    ax.set_zlabel("fitness")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title)
    ax.legend(handles=lon_legend(graph, labels), loc="upper left", fontsize=7)
    return fig


def lon_legend(graph: nx.DiGraph, labels: dict[str, str] | None) -> list[Line2D]:
    """Fig. 3's legend: the behaviour colours (when the nodes carry labels), then what the
    best node, a start node and an edge's shading mean."""
    dot = {"ls": "", "marker": "o"}
    handles = []
    if labels is not None:
        handles += [
            Line2D([], [], **dot, color=label_colour(name), markersize=6, label=name)
            for name in ordered_labels(labels.values())
        ]
        best = Line2D(
            [], [], **dot, markerfacecolor="white", markeredgecolor=INK, markersize=8,
            label="best optimum (outlined, largest)",
        )  # fmt: skip
    else:
        handles.append(Line2D([], [], **dot, color=GREY, markersize=6, label="local optimum"))
        best = Line2D([], [], **dot, color=RED, markersize=8, label="best optimum (red)")
    roles = {role for role, names in _node_roles(graph).items() if names}
    if roles & {"best", "best start"}:
        handles.append(best)
    if roles & {"start", "best start"}:
        handles.append(
            Line2D(
                [],
                [],
                **dot,
                color=GREY,
                markersize=3,
                label="start node: a run's first optimum (small)",
            )
        )
    if graph.number_of_edges():
        handles.append(
            Line2D(
                [], [], color="#505050", lw=1.6,
                label="accepted hop: light at its start, dark towards the optimum it reaches",
            )
        )  # fmt: skip
    return handles


def lon_3d_interactive(
    graph: nx.DiGraph, seed: int = 0, title: str = "3-D LON", hover: dict[str, str] | None = None
):
    """The 3-D LON as an interactive plotly figure (rotate, zoom, hover for node details);
    a notebook shows it inline, :func:`lon_3d_html` writes it as a page. With behaviour
    labels on the nodes, markers take the label's colour (one legend entry per label);
    ``hover`` adds text per node (e.g. its behaviour descriptor)."""
    import plotly.graph_objects as go

    pos = layout_2d(graph, seed)
    traces = []
    xs, ys, zs = [], [], []
    for u, v in graph.edges:
        for node in (u, v):
            xs.append(pos[node][0])
            ys.append(pos[node][1])
            zs.append(graph.nodes[node]["fitness"])
        xs.append(None)
        ys.append(None)
        zs.append(None)
    traces.append(
        go.Scatter3d(
            x=xs,
            y=ys,
            z=zs,
            mode="lines",
            name="transitions",
            line={"color": "#b0b0b0", "width": 2},
            hoverinfo="skip",
        )
    )
    if graph.number_of_edges():
        u_pts = np.array([(*pos[u], graph.nodes[u]["fitness"]) for u, _ in graph.edges])
        v_pts = np.array([(*pos[v], graph.nodes[v]["fitness"]) for _, v in graph.edges])
        direction = v_pts - u_pts
        tips = u_pts + 0.85 * direction
        traces.append(
            go.Cone(
                x=tips[:, 0],
                y=tips[:, 1],
                z=tips[:, 2],
                u=direction[:, 0],
                v=direction[:, 1],
                w=direction[:, 2],
                sizemode="absolute",
                sizeref=0.05,
                showscale=False,
                colorscale=[[0, "#b0b0b0"], [1, "#b0b0b0"]],
                name="direction",
                hoverinfo="skip",
            )
        )
    labels = _labels(graph)
    hover = hover or {}

    def text(n: str) -> str:
        parts = [n, f"fitness {graph.nodes[n]['fitness']:.3f}"]
        if labels is not None:
            parts.append(f"behaviour: {labels[n]}")
        return "<br>".join(parts + ([hover[n]] if n in hover else []))

    for role, names in _node_roles(graph).items():
        if not names:
            continue
        color, _, size, legend = NODE_STYLE[role]
        groups = [(legend, names, color)]
        if labels is not None:
            by_label: dict[str, list[str]] = {}
            for n in names:
                by_label.setdefault(labels[n] or "unlabelled", []).append(n)
            groups = [
                (f"{label} ({legend})", members, label_colour(label))
                for label, members in by_label.items()
            ]
        for name, members, colour in groups:
            traces.append(
                go.Scatter3d(
                    x=[pos[n][0] for n in members],
                    y=[pos[n][1] for n in members],
                    z=[graph.nodes[n]["fitness"] for n in members],
                    mode="markers",
                    name=name,
                    marker={"color": colour, "size": size},
                    text=[text(n) for n in members],
                    hoverinfo="text",
                )
            )
    fig = go.Figure(traces)
    fig.update_layout(
        title=title,
        scene={"zaxis_title": "fitness", "xaxis_visible": False, "yaxis_visible": False},
    )
    return fig


def save_html(fig, path: str | Path) -> Path:
    """Write a plotly figure as a self-contained page (plotly.js embedded, works offline)."""
    path = Path(path)
    fig.write_html(path, include_plotlyjs=True, full_html=True)
    return path


def lon_3d_html(graph: nx.DiGraph, path: str | Path, seed: int = 0, title: str = "3-D LON") -> Path:
    """The 3-D LON as a self-contained interactive page (:func:`lon_3d_interactive`)."""
    return save_html(lon_3d_interactive(graph, seed, title), path)


def fitness_histogram(
    values: np.ndarray,
    title: str,
    bins: int = 50,
    paper_peaks: tuple[float, ...] = PAPER_PEAKS,
    labels: np.ndarray | None = None,
) -> plt.Figure:
    """Figs. 4 and 5: histogram of fitness values on [0, 1] (n in the title, integer counts)
    with detected peaks (black triangles) and the paper's peaks (black dashed lines, each
    labelled with its value); with ``labels`` (one behaviour label per value) the bars are
    stacked by label in the labels' colours."""
    values = np.asarray(values, dtype=float)
    with themed():
        fig, ax = plt.subplots(figsize=(6.5, 3.8))
        handles: list[Any] = []
        if len(values):
            if labels is None:
                frame = pd.DataFrame({"fitness": values})
                hue: dict[str, Any] = {"color": GREY}
            else:
                frame = pd.DataFrame(
                    {"fitness": values, "label": np.asarray(labels, dtype=object).astype(str)}
                )
                present = ordered_labels(frame["label"])
                hue = {
                    "hue": "label",
                    "hue_order": present,
                    "palette": {name: label_colour(name) for name in present},
                    "multiple": "stack",
                }
                handles += [Patch(color=label_colour(name), label=name) for name in present]
            sns.histplot(
                data=frame, x="fitness", bins=bins, binrange=(0, 1), stat="count",
                edgecolor="white", linewidth=0.5, alpha=1.0, legend=False, ax=ax, **hue,
            )  # fmt: skip
        peaks = detect_peaks(values, bins=bins)
        if len(peaks):
            ax.plot(peaks["fitness"], peaks["count"] + 0.3, "v", color=INK, markersize=6)
            handles.append(Line2D([], [], ls="", marker="v", color=INK, label="detected peak"))
        for peak in paper_peaks:
            ax.axvline(peak, color=INK, linestyle="--", linewidth=0.8)
            ax.text(
                peak, 1.0, f"{peak:g}", transform=ax.get_xaxis_transform(), ha="center",
                va="bottom", fontsize=7, color=INK,
            )  # fmt: skip
        if paper_peaks:
            handles.append(Line2D([], [], color=INK, ls="--", lw=0.8, label="paper's peaks"))
        ax.set_xlim(0, 1)
        ax.set_ylim(0, max(1.0, ax.get_ylim()[1]))
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel("fitness")
        ax.set_ylabel("count")
        ax.set_title(f"{title} (n = {len(values)})", pad=14)
        if handles:
            ax.legend(handles=handles, fontsize=7, loc="upper right")
        fig.tight_layout()
    return fig


def sensitivity(
    metrics: pd.DataFrame,
    columns: tuple[str, ...] = (
        "optima",
        "sinks",
        "best",
        "success",
        "global_funnel_proportion",
        "neutral",
    ),
) -> plt.Figure:
    """LON metrics against the perturbation strength (log scale), one panel per metric."""
    table = metrics.sort_values("p")
    with themed():
        fig, axes = plt.subplots(1, len(columns), figsize=(3 * len(columns), 3))
        for ax, column in zip(np.atleast_1d(axes), columns, strict=True):
            sns.lineplot(data=table, x="p", y=column, marker="o", color=INK, ax=ax)
            ax.set_xscale("log")
            ax.set_xlabel("perturbation strength p")
            ax.set_ylabel("")
            ax.set_title(column)
        fig.tight_layout()
    return fig


def nominal_beside_robust(
    nominal: np.ndarray, robust: np.ndarray, title: str, bins: int = 50
) -> plt.Figure:
    """Figs. 4-5 under both fitness estimates: the histogram of the nominal fitness (what
    the LON's nodes carry) and, beside it, of the same optima's robust mean (the fitness
    over the perturbed starts), on one fitness axis and one count axis."""
    with themed():
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.5), sharex=True, sharey=True)
        for ax, values, name in zip(
            axes, (nominal, robust), ("nominal", "robust mean"), strict=True
        ):
            ax.hist(np.asarray(values, dtype=float), bins=bins, range=(0, 1), color=GREY)
            ax.set_xlabel(f"fitness ({name})")
            ax.set_title(f"{title}: {name} (n = {len(values)})", fontsize=9)
            ax.yaxis.get_major_locator().set_params(integer=True)
        axes[0].set_ylabel("count")
        fig.tight_layout()
    return fig


def retention_plot(curve: pd.DataFrame) -> plt.Figure:
    """The retention curve: per start-noise level, the share of optima keeping at least
    half their nominal fitness, one line per p (``curve`` has ``p``, ``noise``,
    ``keep_share``)."""
    with themed():
        fig, ax = plt.subplots(figsize=(6, 3.5))
        for p, group in curve.groupby("p", sort=True):
            ax.plot(
                group["noise"],
                group["keep_share"],
                "o-",
                label=f"p = {p:g} (n = {group['optima'].iloc[0]})",
            )
        ax.set_xscale("log")
        ax.set_ylim(0, 1.02)
        ax.set_xlabel("start noise (half-width of U[-noise, noise] on x, x_dot, phi, phi_dot)")
        ax.set_ylabel("share keeping >= 1/2 fitness")
        ax.set_title("Conditioning of the LON's nodes")
        ax.legend(fontsize=8)
        fig.tight_layout()
    return fig


def claim_d_curve_plot(
    curve: pd.DataFrame, epsilon: float, max_share: float, title: str = "Claim d over epsilon"
) -> plt.Figure:
    """Claim d's curve: per epsilon, the share of behaviour nodes entered from more than
    one other node, one line per p (``curve`` from :func:`lonlib.analysis.claims.claim_d_curve`:
    ``p``, ``epsilon``, ``share``, ``nodes``; with ``ci_low``/``ci_high`` a band), the
    pre-registered ``epsilon`` as a vertical line and the largest share "sparse" allows
    (``max_share``) as a horizontal one."""
    with themed():
        fig, ax = plt.subplots(figsize=(6, 3.5))
        for p, group in curve.groupby("p", sort=True):
            (line,) = ax.plot(group["epsilon"], group["share"], "o-", label=f"p = {p_label(p)}")
            if {"ci_low", "ci_high"} <= set(group.columns):
                ax.fill_between(
                    group["epsilon"], group["ci_low"], group["ci_high"], color=line.get_color(),
                    alpha=0.15, linewidth=0,
                )  # fmt: skip
        ax.axvline(epsilon, color=GREY, linestyle="--", linewidth=1, label=f"epsilon = {epsilon:g}")
        ax.axhline(
            max_share, color=RED, linestyle=":", linewidth=1, label=f"sparse: <= {max_share:g}"
        )
        ax.set_ylim(0, 1.02)
        ax.set_xlabel("epsilon (standard deviations, standardised behaviour features)")
        ax.set_ylabel("share of multi-inward nodes")
        ax.set_title(title)
        ax.legend(fontsize=8)
        fig.tight_layout()
    return fig
