"""The paper's analysis of a stored experiment: peaks, statistics, claims, summary, figures,
recordings and verification (no torch)."""

from lonlib.analysis.claims import Claim, claims_from_trials, paper_claims
from lonlib.analysis.claims_power import power_table
from lonlib.analysis.claims_report import claims_markdown
from lonlib.analysis.conditioning import conditioning_by_label
from lonlib.analysis.holding import CHATTER_TOLERANT, holding_markdown, holding_summary
from lonlib.analysis.landscape import Landscape, StoredExperiment, landscapes
from lonlib.analysis.peaks import detect_peaks
from lonlib.analysis.pipeline import (
    Analysis,
    analyse,
    load_experiment,
    optima_to_record,
    record_optima,
)
from lonlib.analysis.plots import optima_boxplot
from lonlib.analysis.recordings import record, recorded_entities, show_inline
from lonlib.analysis.summary import experiment_summary, summary_markdown
from lonlib.analysis.verify import VerifyReport, verify_experiment

__all__ = [
    "Analysis",
    "CHATTER_TOLERANT",
    "Claim",
    "Landscape",
    "StoredExperiment",
    "VerifyReport",
    "analyse",
    "claims_from_trials",
    "claims_markdown",
    "conditioning_by_label",
    "detect_peaks",
    "experiment_summary",
    "holding_markdown",
    "holding_summary",
    "landscapes",
    "load_experiment",
    "optima_boxplot",
    "optima_to_record",
    "paper_claims",
    "power_table",
    "record",
    "record_optima",
    "recorded_entities",
    "show_inline",
    "summary_markdown",
    "verify_experiment",
]
