"""Output, written while a run goes: the observers of its steps (progress, fields, stations, InSAR raster,
checkpoint, summary), the XDMF/HDF5 series, the run's metadata, the GIS/NetCDF writers, a restart's checks of the
run it continues, and the InSAR product whose pixels a raster takes. What is made from a run directory afterwards
is pfault.post."""
