"""lonlib.calibration: the calibration study, the learner-side study and the hold test."""
