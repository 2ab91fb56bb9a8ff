#!/usr/bin/env bash
# Installs what pfault needs on Debian 12, once: Debian's PETSc stack, OpenBLAS, and a venv
# (system site packages) holding pfault (editable) and what it takes from PyPI: gmsh, meshio, scipy (spatial
# fields, least squares of python -m pfault.calibrate), pytest and pytest-xdist, matplotlib (figures), flopy (MODFLOW head and grid
# files), h5netcdf (the InSAR raster, NetCDF-4 through h5py), pyproj (-pfault_crs: PROJ's coordinate reference
# systems), rasterio (GeoTIFFs), netCDF4 (the tests read the raster back with the netCDF library), xarray (the tests
# write MODFLOW 6 NetCDF heads) and pyemu (the tests read the calibration's PEST++ files back); Debian's GDAL
# (gdal-bin, python3-gdal: the tests read the GIS layers back as QGIS does). Optional: PFAULT_GETFEM=1 also
# installs Debian's python3-getfem, the peer code of benchmarks/frictional_crack.py (the venv sees it).
# Half a second when ready.
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
PKGS="python3-petsc4py-real python3-petsc4py python3-mpi4py python3-h5py-mpi petsc-dev python3-venv libopenblas0-pthread"
PKGS="$PKGS gdal-bin python3-gdal"
if [ "${PFAULT_GETFEM:-0}" = "1" ]; then PKGS="$PKGS python3-getfem"; fi
missing=""
for p in $PKGS; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then missing="$missing $p"; fi
done
if [ -n "$missing" ]; then
  echo "setup: installing Debian packages:$missing"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing >/dev/null
fi
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv (with system site packages: Debian's petsc4py, mpi4py, numpy, h5py)"
  /usr/bin/python3 -m venv --system-site-packages .venv
fi
PYPI="gmsh meshio scipy>=1.10,<1.12 pytest pytest-xdist matplotlib flopy h5netcdf netCDF4 pyemu pyproj>=3.6 rasterio>=1.3 xarray"
# ready when every distribution is installed in its version range (their metadata, read in 0.2 s; importing them all
# to find out took 2.7-3.4 s of every main job and test run)
if ! .venv/bin/python - $PYPI >/dev/null 2>&1 <<'EOF'
import sys
from importlib.metadata import version
from packaging.requirements import Requirement
sys.exit(0 if all(r.specifier.contains(version(r.name), prereleases=True) for r in map(Requirement, sys.argv[1:])) else 1)
EOF
then
  echo "setup: installing $PYPI into .venv"
  # numpy stays Debian's (petsc4py is compiled against it): pinned on the same pip command; scipy held to the
  # series tested with Debian 12's numpy 1.24 (1.10-1.11; scipy 1.16 and later cannot install beside it)
  .venv/bin/pip install -q --disable-pip-version-check $PYPI "numpy==$(.venv/bin/python -c 'import numpy; print(numpy.__version__)')"
fi
if ! .venv/bin/python -I -c "import pfault, sys; sys.exit(0 if pfault.__file__.startswith('$PWD') else 1)" >/dev/null 2>&1; then
  .venv/bin/pip install -q --disable-pip-version-check --no-build-isolation --no-deps -e .
fi
# pfault's (and the studies') bytecode, written whatever PYTHONDONTWRITEBYTECODE says: where it is set, every
# process compiled every pfault module it imported (0.15 s of a small run's 1.0 s); 0.06 s when up to date
.venv/bin/python -m compileall -q pfault studies >/dev/null
