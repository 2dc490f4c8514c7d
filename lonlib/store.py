"""Moved to :mod:`lonlib.storage.store`; this name stays importable for code written before the
subpackages (the golden test among it): it is that module, not a copy."""

import sys

from lonlib.storage import store as moved

sys.modules[__name__] = moved
