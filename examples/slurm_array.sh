#!/usr/bin/env bash
# A Slurm job array over one blurset build: each array task renders a disjoint share of
# the objects (`--shard i/N`, a partition of the sorted object ids) into one shared OUT.
# Resubmitting the same array resumes it: complete settings are skipped, partial ones
# redone. Submit with:   sbatch --array=0-63 examples/slurm_array.sh
#SBATCH --job-name=blurset
#SBATCH --cpus-per-task=8
#SBATCH --mem=16G
#SBATCH --time=24:00:00
#SBATCH --output=logs/blurset-%A_%a.out
set -euo pipefail

OUT=${OUT:-/shared/datasets/objaverse_blur}       # a filesystem every node sees
OBJECTS=${OBJECTS:-objaverse:lvis=chair+mug+shoe}  # files, folders, lists or objaverse ids
N=${SLURM_ARRAY_TASK_COUNT:?run as a job array}
I=${SLURM_ARRAY_TASK_ID:?run as a job array}

# The objaverse cache must be shared too, or each node downloads its own copies.
.venv/bin/blurset build --objects "$OBJECTS" --out "$OUT" \
  --objaverse-dir /shared/objaverse --objaverse-count 250 --seed 0 \
  --threads "${SLURM_CPUS_PER_TASK}" --shard "$I/$N" --quiet
