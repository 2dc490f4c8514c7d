"""Moved to :mod:`lonlib.storage.result_path`; this name stays importable for code written before
the subpackages (the golden test among it): it is that module, not a copy."""

import sys

from lonlib.storage import result_path as moved

sys.modules[__name__] = moved
