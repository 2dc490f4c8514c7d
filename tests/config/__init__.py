"""lonlib.config: configurations, their validation and YAML loading (fuzzed, hostile files)."""
