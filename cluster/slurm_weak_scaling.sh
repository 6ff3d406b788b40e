#!/bin/bash
# Weak scaling: a fixed number of particles per rank (default 1e6: 50^3 cells x 8 per rank), the box grown
# with the rank count. One run per node count (loop inside one allocation, or a job array as below).
#   sbatch --nodes=32 cluster/slurm_weak_scaling.sh                  (loops over 1 2 4 8 16 32 nodes)
#   sbatch --array=0-5 --nodes=32 cluster/slurm_weak_scaling.sh      (one array task per node count)
# Each run writes into $ROOT/np<ranks>/output.txt and log_view.txt;
# afterwards: python3 cluster/collect_scaling.py --mode weak $ROOT > weak.csv
#SBATCH --job-name=granmpm-weak
#SBATCH --ntasks-per-node=32
#SBATCH --cpus-per-task=1
#SBATCH --exclusive
#SBATCH --time=02:00:00
#SBATCH --output=granmpm-weak-%A_%a.out
set -euo pipefail
# module load gcc openmpi petsc hdf5          # site specific
export OMP_NUM_THREADS=1

GRANMPM=${GRANMPM:-build/granmpm}
ROOT=${ROOT:-runs/weak}
NODE_COUNTS=(${NODE_COUNTS:-1 2 4 8 16 32})
TPN=${SLURM_NTASKS_PER_NODE:-32}
C=${CELLS_PER_RANK:-50}                       # cells per direction of one rank block (2 PPC per direction -> 8 C^3 particles)

run_one() {
  local nodes=$1 np=$(($1 * TPN))
  # factor np = px*py*pz as evenly as possible so that every rank block is C^3 cells
  read -r px py pz < <(python3 -c "
import sys
n = $np; best = None
for x in range(1, n + 1):
    if n % x: continue
    for y in range(1, n // x + 1):
        if (n // x) % y: continue
        z = n // x // y; s = max(x, y, z) - min(x, y, z)
        if best is None or s < best[0]: best = (s, x, y, z)
print(*best[1:])")
  local out=$ROOT/np$np
  mkdir -p "$out"
  srun --nodes="$nodes" --ntasks="$np" --cpu-bind=cores "$GRANMPM" -dim 3 -scene block -material elastic \
    -E 1e6 -nu 0.3 -rho 1500 -domain_lo 0,0,0 -domain_hi "$px,$py,$pz" -cells "$((px * C)),$((py * C)),$((pz * C))" \
    -da_processors_x "$px" -da_processors_y "$py" -da_processors_z "$pz" \
    -ppc 2 -shape bspline2 -transfer apic -update usl -gravity 0,0,0 -gravity_ramp 0 -velocity 3,2,1 -spin 0 \
    -dt "$(python3 -c "print(0.25 / $C / 29.96)")" -t_end 1e9 -max_steps "${STEPS:-50}" \
    -bc_xlo periodic -bc_xhi periodic -bc_ylo periodic -bc_yhi periodic -bc_zlo periodic -bc_zhi periodic \
    -output_final 0 -progress_interval 0 -output_dir "$out" -log_view :"$out"/log_view.txt "$@" > "$out"/output.txt 2>&1
}

if [ -n "${SLURM_ARRAY_TASK_ID:-}" ]; then
  run_one "${NODE_COUNTS[$SLURM_ARRAY_TASK_ID]}" "$@"
else
  for n in "${NODE_COUNTS[@]}"; do
    [ "$n" -le "${SLURM_NNODES:-1}" ] && run_one "$n" "$@"
  done
fi
