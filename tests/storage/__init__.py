"""lonlib.storage: the result path, manifests and sessions, thinning, stored policies."""
