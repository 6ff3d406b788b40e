#!/bin/bash
# Multi-node GranMPM run: the template for production runs on several nodes. Submit with sbatch;
# adjust the #SBATCH lines and the environment block to the site.
#SBATCH --job-name=granmpm
#SBATCH --nodes=4
#SBATCH --ntasks-per-node=32          # one rank per physical core (no hyper-threads)
#SBATCH --cpus-per-task=1
#SBATCH --exclusive
#SBATCH --time=12:00:00
#SBATCH --signal=TERM@120             # SIGTERM 120 s before the time limit: GranMPM writes a checkpoint and exits
#SBATCH --output=granmpm-%j.out
set -euo pipefail

# --- site environment (examples; uncomment/adapt) ----------------------------------------------
# module purge
# module load gcc openmpi petsc hdf5        # PETSc >= 3.18 built with HDF5 and hypre, the same MPI
# export PETSC_DIR=/path/to/petsc PETSC_ARCH=arch-opt
export OMP_NUM_THREADS=1                     # GranMPM is MPI-only; keep BLAS/hypre from spawning threads
# export UCX_TLS=rc,sm,self                  # InfiniBand transport selection, if the site recommends it

GRANMPM=${GRANMPM:-build/granmpm}
SCENE=${SCENE:-examples/block_3d.opts}
OUT=${OUT:-runs/$SLURM_JOB_ID}
mkdir -p "$OUT"

# Resume from the last checkpoint if this is a requeued/resubmitted job writing into the same OUT.
RESTART=()
if [ -f "$OUT/checkpoint.h5" ]; then RESTART=(-restart "$OUT/checkpoint.h5"); fi

# srun is the normal launcher under SLURM (binding by SLURM); with mpirun instead:
#   mpirun -n "$SLURM_NTASKS" --bind-to core --map-by core "$GRANMPM" ...
srun --cpu-bind=cores "$GRANMPM" -options_file "$SCENE" -output_dir "$OUT" \
  -checkpoint_interval "${CHECKPOINT_INTERVAL:-1000}" "${RESTART[@]}" \
  -log_view :"$OUT"/log_view.txt "$@"
