"""lonlib's informational messages (logger ``lonlib``) shown on stderr."""

import logging


def show_lonlib_messages() -> None:
    """Print lonlib's informational messages (a resumed batch, a stale checkpoint) on
    stderr, once per process."""
    logger = logging.getLogger("lonlib")
    if not logger.handlers:
        handler = logging.StreamHandler()
        handler.setFormatter(logging.Formatter("lonlib: %(message)s"))
        logger.addHandler(handler)
        logger.setLevel(logging.INFO)
