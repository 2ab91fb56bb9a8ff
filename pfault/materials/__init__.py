"""Materials: what each cell is made of.

- ``properties``: the material properties per cell, a number per material or a spatial field interpolated at the
  cell centroids (CellProperties, built once by the model);
- ``field_files``: the readers of the fields' files (CSV, HDF5, NetCDF; points or a regular grid).
"""
