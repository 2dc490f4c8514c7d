"""lonlib.cli: the lonlib command line as a user meets it."""
