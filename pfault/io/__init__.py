"""Output: XDMF/HDF5 time series, summary.json, run metadata."""
