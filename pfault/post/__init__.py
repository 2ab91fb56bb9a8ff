"""Post-processing: what is made from a run directory's files, at the end of a run or afterwards.

- ``figures``: the PNG figures of a run (``python -m pfault.post.figures RUN_DIR``);
- ``fissures``: the fissures that formed, measured and drawn;
- ``gis``: the GIS layers of a run with a CRS (``python -m pfault.post.gis RUN_DIR``).

Nothing that runs the time loop imports this package; it reads the files pfault.io writes.
"""
