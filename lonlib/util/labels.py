"""Formatters of labels shared by the layers: a perturbation strength's folder-safe label."""


def p_label(p: float) -> str:
    """Folder-safe, exact label of a perturbation strength (``1e-04``)."""
    return f"{p:.6g}".replace("e-0", "e-")
