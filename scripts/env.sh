# Environment for running pfault under Open MPI on this machine (sourced by the scripts).
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1
if [ "$(id -u)" -eq 0 ]; then
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
fi
# quiet Open MPI's warnings about missing high-speed network devices in containers
export OMPI_MCA_btl_vader_single_copy_mechanism=none
