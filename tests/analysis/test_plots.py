"""Figure functions return figures with the expected content; peak detection."""

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Path3DCollection  # noqa: E402

from lonlib.analysis.peaks import PAPER_PEAKS, compare_with_paper, detect_peaks  # noqa: E402
from lonlib.analysis.plots import (  # noqa: E402
    claim_d_curve_plot,
    fitness_histogram,
    lon_3d,
    lon_3d_html,
    optima_boxplot,
    sensitivity,
)
from lonlib.lon.graphs import build_lon  # noqa: E402
from tests.lon.test_lon import HAND, trials  # noqa: E402


def test_boxplot_has_one_box_per_p_and_labels():
    sample = trials([(0, 0, -1, 0.3, True), (0, 1, 0, 0.4, True)], p=1e-3)
    table = __import__("pandas").concat([HAND, sample])
    fig = optima_boxplot(table)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "perturbation strength p"
    assert ax.get_ylabel() == "local optimum fitness"
    ticks = [t.get_text() for t in ax.get_xticklabels()]
    accepted = table[table["accepted"]]
    optima, runs = len(accepted[accepted["p"] == 1e-4]), accepted[accepted["p"] == 1e-4]["run"]
    assert ticks[0] == "0.001\nn = 2 optima, 1 run"
    assert ticks[1] == f"0.0001\nn = {optima} optima, {runs.nunique()} runs"
    # every accepted optimum a point, and each run's best marked once more
    points = sum(len(c.get_offsets()) for c in ax.collections)
    assert points == len(accepted) + accepted.groupby(["p", "run"]).ngroups
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend == ["accepted optimum", "a run's best"]


def test_figures_are_byte_stable_for_the_same_data():
    from lonlib.util.figures import png_bytes

    table = __import__("pandas").concat(
        [HAND, trials([(0, 0, -1, 0.3, True), (0, 1, 0, 0.4, True)], p=1e-3)]
    )
    assert png_bytes(optima_boxplot(table)) == png_bytes(optima_boxplot(table))
    values = np.linspace(0.1, 0.9, 40)
    assert png_bytes(fitness_histogram(values, "t")) == png_bytes(fitness_histogram(values, "t"))
    assert b"Matplotlib" not in png_bytes(fitness_histogram(values, "t"))  # no version inside


def test_lon_3d_draws_every_node_with_fitness_as_height(tmp_path):
    graph = build_lon(HAND)
    fig = lon_3d(graph)
    ax = fig.axes[0]
    scatters = [c for c in ax.collections if isinstance(c, Path3DCollection)]
    heights = np.concatenate([c._offsets3d[2] for c in scatters])
    assert len(heights) == graph.number_of_nodes()
    assert sorted(heights) == sorted(f for _, f in graph.nodes(data="fitness"))
    assert ax.get_zlabel() == "fitness"
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(text.startswith("best optimum") for text in legend)
    assert any(text.startswith("start node") for text in legend)
    assert any("dark towards the optimum" in text for text in legend)
    html = lon_3d_html(graph, tmp_path / "lon.html").read_text()
    assert "plotly" in html and len(html) > 100_000  # plotly.js embedded: works offline


def test_histograms_mark_detected_and_paper_peaks():
    from lonlib.analysis.plots import INK, LABEL_COLOURS

    rng = np.random.default_rng(0)
    values = np.concatenate([rng.normal(peak, 0.01, 100) for peak in PAPER_PEAKS])
    peaks = detect_peaks(values)
    assert len(peaks) == 5
    table = compare_with_paper(peaks)
    assert (table["distance"] <= 0.02).all()
    fig = fitness_histogram(values, "sinks")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "fitness" and ax.get_ylabel() == "count"
    assert ax.get_title() == "sinks (n = 500)"
    dashed = [line for line in ax.lines if line.get_linestyle() == "--"]
    assert len(dashed) == 5
    # the paper's peaks are labelled with their values, in a colour no behaviour uses
    assert [t.get_text() for t in ax.texts] == [f"{p:g}" for p in PAPER_PEAKS]
    assert INK not in LABEL_COLOURS.values()
    assert all(line.get_color() == INK for line in dashed)
    # the count axis has integer ticks only, also with a handful of values
    few = fitness_histogram(np.array([0.2, 0.21, 0.5]), "few").axes[0]
    assert all(float(t).is_integer() for t in few.get_yticks())


def test_peaks_at_the_edges_and_empty_input():
    assert list(detect_peaks(np.zeros(30))["fitness"]) == pytest.approx([0.01])
    assert detect_peaks(np.array([])).empty
    assert compare_with_paper(detect_peaks(np.array([])))["nearest_detected"].isna().all()


def test_sensitivity_has_a_panel_per_metric():
    import pandas as pd

    metrics = pd.DataFrame(
        {
            "p": [1e-4, 1e-3, 1e-2],
            "optima": [3, 4, 5],
            "sinks": [1, 2, 3],
            "best": [0.5, 0.4, 0.3],
            "success": [1, 0.5, 0.2],
            "global_funnel_proportion": [1, 1, 0.5],
            "neutral": [0, 0, 0.1],
        }
    )
    fig = sensitivity(metrics)
    assert len(fig.axes) == 6 and fig.axes[0].get_xscale() == "log"


def test_claim_d_curve_has_a_line_per_p_and_marks_the_preregistered_epsilon():
    import pandas as pd

    curve = pd.DataFrame(
        {
            "p": [1e-4] * 3 + [1e-3] * 3,
            "epsilon": [0.1, 0.5, 1.0] * 2,
            "nodes": [20, 18, 15, 21, 21, 19],
            "share": [0.0, 0.05, 0.2, 0.0, 0.0, 0.1],
            "ci_low": [0.0, 0.003, 0.06, 0.0, 0.0, 0.02],
            "ci_high": [0.14, 0.24, 0.43, 0.13, 0.13, 0.30],
        }
    )
    fig = claim_d_curve_plot(curve, epsilon=0.5, max_share=0.05)
    ax = fig.axes[0]
    labels = [line.get_label() for line in ax.lines]
    assert labels == ["p = 0.0001", "p = 0.001", "epsilon = 0.5", "sparse: <= 0.05"]
    assert list(ax.lines[0].get_ydata()) == [0.0, 0.05, 0.2]
    assert list(ax.lines[2].get_xdata()) == [0.5, 0.5] and len(ax.collections) == 2


def test_figures_colour_and_stack_by_behaviour_label():
    from lonlib.analysis.pipeline import optima_to_record, slug
    from lonlib.analysis.plots import label_colour, lon_3d_interactive
    from lonlib.analysis.recordings import recording_name
    from tests.task.test_behaviour import labelled_trials

    table = labelled_trials()
    graph = build_lon(table)
    fig = lon_3d_interactive(graph, hover={"p0.0001_r0_t3": "rod 0: up 90%"})
    markers = [t for t in fig.data if t.type == "scatter3d" and t.mode == "markers"]
    shown = {t.name.split(" (")[0] for t in markers}
    assert {"balancing", "spinning", "swinging high"} <= shown
    balancing = next(t for t in markers if t.name.startswith("balancing"))
    assert balancing.marker.color == label_colour("balancing")
    assert "behaviour: balancing" in balancing.text[0] and "rod 0: up 90%" in balancing.text[0]
    accepted = table[table["accepted"]]
    hist = fitness_histogram(accepted["fitness"].to_numpy(), "t", labels=accepted["label"])
    legend = [t.get_text() for t in hist.axes[0].get_legend().get_texts()]
    assert legend[:4] == ["balancing", "spinning (in phase)", "spinning", "swinging high"]
    chosen = optima_to_record(table)
    assert set(chosen["behaviour"]) == set(accepted["label"])  # the best of every label
    assert {"best", "label-best"} <= set(chosen["role"])
    names = {
        recording_name(r.p, r.run, r.fitness, role=r.role, behaviour=slug(r.behaviour))
        for r in chosen.itertuples()
    }
    # one scheme: <role>_<behaviour>_optimum_..., file-name safe (no parentheses)
    assert any(n.startswith("label-best_spinning-in-phase_optimum_p=") for n in names)
    assert any(n.startswith("label-best_swinging-high_optimum_p=") for n in names)


def test_boxplot_marks_each_runs_best_once_whatever_the_tables_index():
    table = __import__("pandas").concat([HAND, HAND.assign(run=HAND["run"] + 10)])
    table.index = [0] * len(table)  # e.g. tables concatenated without ignore_index
    accepted = table[table["accepted"]]
    fig = optima_boxplot(table)
    points = sum(len(c.get_offsets()) for c in fig.axes[0].collections)
    assert points == len(accepted) + accepted.groupby(["p", "run"]).ngroups
