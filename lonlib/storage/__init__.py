"""What an experiment stores and how it is read back (no torch): configurations, the folder
layout, atomic storage of runs, the manifest, locks, provenance and the result-path version."""
