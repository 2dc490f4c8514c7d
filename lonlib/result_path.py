"""The result-path version: one string that changes whenever a change alters trials or
stored numbers (placeholder; the lock branch defines the golden test)."""

RESULT_PATH_VERSION = "2"
