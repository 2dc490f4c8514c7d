"""lonlib.lon: LONs, their metrics, trace and graph files, behaviour nodes."""
