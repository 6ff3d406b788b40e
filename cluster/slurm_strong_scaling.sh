#!/bin/bash
# Strong scaling: the same problem on 1, 2, 4, ... nodes, one array task per node count.
#   sbatch --array=0-4 --nodes=16 cluster/slurm_strong_scaling.sh          (allocation sized for the largest task)
# or, without job arrays, one job per node count:
#   for n in 1 2 4 8 16; do sbatch --nodes=$n --export=ALL,NODES=$n cluster/slurm_strong_scaling.sh; done
# Each run writes into $ROOT/np<ranks>/ (solver stdout in output.txt, -log_view in log_view.txt);
# afterwards: python3 cluster/collect_scaling.py --mode strong $ROOT > strong.csv
#SBATCH --job-name=granmpm-strong
#SBATCH --ntasks-per-node=32
#SBATCH --cpus-per-task=1
#SBATCH --exclusive
#SBATCH --time=01:00:00
#SBATCH --output=granmpm-strong-%A_%a.out
set -euo pipefail
# module load gcc openmpi petsc hdf5          # site specific
export OMP_NUM_THREADS=1

GRANMPM=${GRANMPM:-build/granmpm}
ROOT=${ROOT:-runs/strong}
NODE_COUNTS=(${NODE_COUNTS:-1 2 4 8 16})
TPN=${SLURM_NTASKS_PER_NODE:-32}
if [ -n "${SLURM_ARRAY_TASK_ID:-}" ]; then NODES=${NODE_COUNTS[$SLURM_ARRAY_TASK_ID]}; else NODES=${NODES:-${SLURM_NNODES:-1}}; fi
NP=$((NODES * TPN))
# Fixed problem: 3D elastic block, 200^3 cells x 8 particles = 6.4e7 particles (>= 1e5 per rank up to 640 ranks).
CELLS=${CELLS:-200,200,200}
OUT=$ROOT/np$NP
mkdir -p "$OUT"
srun --nodes="$NODES" --ntasks="$NP" --cpu-bind=cores "$GRANMPM" -dim 3 -scene block -material elastic \
  -E 1e6 -nu 0.3 -rho 1500 -domain_lo 0,0,0 -domain_hi 1,1,1 -cells "$CELLS" -ppc 2 -shape bspline2 -transfer apic -update usl \
  -gravity 0,0,0 -gravity_ramp 0 -velocity 3,2,1 -spin 1 -dt 2e-5 -t_end 1e9 -max_steps "${STEPS:-50}" \
  -bc_xlo periodic -bc_xhi periodic -bc_ylo periodic -bc_yhi periodic -bc_zlo periodic -bc_zhi periodic \
  -output_final 0 -progress_interval 0 -output_dir "$OUT" -log_view :"$OUT"/log_view.txt "$@" > "$OUT"/output.txt 2>&1
