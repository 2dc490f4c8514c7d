"""The project as a whole: the README and docs, the import layout, public names, static types."""
