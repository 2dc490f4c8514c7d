"""lonlib.util: small utilities (byte-stable figures, notebook paths)."""
