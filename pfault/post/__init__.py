"""Post-processing: what is made from a run directory's files, at the end of a run (pfault.simulation) or afterwards.

- ``rundir``: the reader of a run directory (summary.json, options.txt, the series, the stations), which the
  figures, the GIS layers, the tools, the studies and the tests use;
- ``meshes``: the geometry of the run's meshes (land surface, fault faces, jumps across a fault);
- ``plots``: what the figures share (pyplot on Agg, a PNG written whole, titles);
- ``fissures``: the fissures that formed, measured and drawn;
- ``figures``: the PNG figures of a run (``python -m pfault.post.figures RUN_DIR``);
- ``gis``: the GIS layers of a run with a CRS (``python -m pfault.post.gis RUN_DIR``).

It reads the files pfault.io writes and imports neither PETSc nor MPI; the model, the time loop and pfault.io do
not import it.
"""
