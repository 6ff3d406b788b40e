#!/bin/bash
# Single-node GranMPM run. Adjust the module lines to the site; submit with sbatch.
#SBATCH --job-name=granmpm
#SBATCH --nodes=1
#SBATCH --ntasks-per-node=32
#SBATCH --time=01:00:00
#SBATCH --output=granmpm-%j.out
set -euo pipefail
# module load petsc/3.18 openmpi hdf5-mpi     # site specific
SCENE=${SCENE:-examples/chute_nonlocal.opts}
OUT=${OUT:-runs/$SLURM_JOB_ID}
mkdir -p "$OUT"
srun build/granmpm -options_file "$SCENE" -output_dir "$OUT" -log_view :"$OUT"/log_view.txt "$@"
