"""The project as a whole: the README and docs (their commands, names, paths, examples,
generated blocks and every number about stored results), the import layout, public names,
static types."""
