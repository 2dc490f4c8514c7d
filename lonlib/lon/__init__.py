"""Local Optima Networks: the three graphs (LON, MLON, CMLON), the field's metrics, file
formats, and the behavioural LON."""

from lonlib.lon.behaviour import behavioural_lon
from lonlib.lon.behaviour_space import (
    BehaviourNodes,
    behaviour_node_curve,
    behaviour_nodes,
    transitions,
)
from lonlib.lon.graphs import (
    Compressed,
    Transitions,
    build_lon,
    cmlon,
    compress,
    lon_from_transitions,
    mlon,
    sinks,
)
from lonlib.lon.io import from_trace, read_trace, to_graphml, to_igraph, to_trace
from lonlib.lon.metrics import funnel_metrics, lon_metrics, metrics_table, node_metrics

__all__ = [
    "BehaviourNodes",
    "Compressed",
    "Transitions",
    "behaviour_node_curve",
    "behaviour_nodes",
    "behavioural_lon",
    "build_lon",
    "cmlon",
    "compress",
    "from_trace",
    "funnel_metrics",
    "lon_from_transitions",
    "lon_metrics",
    "metrics_table",
    "mlon",
    "node_metrics",
    "read_trace",
    "sinks",
    "to_graphml",
    "to_igraph",
    "to_trace",
    "transitions",
]
