"""lonlib.search: Algorithm 2 (basin hopping over local searches)."""
