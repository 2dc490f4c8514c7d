"""Small helpers every layer may use: field checks, portable float64 math, progress bars,
the data folder, generated Markdown tables, the pinned CPU kernels."""
