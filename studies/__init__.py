"""Studies built on pfault runs, kept beside the package (they read the repository's config/ and tests/scripts/
and write reports under runs/): the two case studies of Franceschini et al. (Proc. IAHS 372, 2015) against the
paper (``casestudies``), the contact solver's hard cases (``hard_cases``), accuracy against cost on
problems with a known answer (``accuracy``), and the soil law with memory against the 1-D compression-index law,
MODFLOW 6 CSUB's no-delay interbeds and Modified Cam-Clay (``soil_column``, ``soil_laws``: NumPy only, no run).
Their runs are started by pfault.tools.runs (mpirun, environment, logs, timeouts), as the benchmarks' and the
tests' are.

Run them from the repository root: ``python -m studies.casestudies``, or through benchmarks/*.py."""

import os

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))      # the repository's root
