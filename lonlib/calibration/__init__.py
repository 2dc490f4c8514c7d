"""The calibration study of the physics and its report."""
