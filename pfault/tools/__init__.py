"""Tools that run pfault many times: calibration (python -m pfault.calibrate) and the runs they make; and the writers
of synthetic MODFLOW 6 and InSAR files for tests and examples."""
