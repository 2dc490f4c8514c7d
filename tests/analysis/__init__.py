"""lonlib.analysis: the claims and their power, summary, holding, plots, recordings, verify."""
