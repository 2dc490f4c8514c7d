"""The global search: parameter-level basin hopping (paper Algorithm 2)."""
