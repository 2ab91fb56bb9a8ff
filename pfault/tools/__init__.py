"""Tools that run pfault many times: calibration (python -m pfault.calibrate) and the runs they make."""
