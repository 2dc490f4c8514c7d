"""The paper's analysis of a stored experiment: peaks, statistics, claims, summary, figures,
recordings and verification (no torch)."""
