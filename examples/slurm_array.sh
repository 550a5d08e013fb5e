#!/usr/bin/env bash
# A Slurm job array over one blurset build: each array task renders a disjoint share of
# the objects (`--shard i/N`, a partition of the sorted object ids) into one shared OUT.
# Resubmitting the same array resumes it: complete settings are skipped, partial ones
# redone. Submit with:   sbatch --array=0-63 examples/slurm_array.sh
#
# One GPU per task: Slurm gives each task its own GPU (--gres=gpu:1 sets
# CUDA_VISIBLE_DEVICES), `--device auto` renders on the best backend Cycles finds there
# (OptiX > CUDA > HIP > oneAPI > Metal > CPU) and meta.json records which. Name the backend
# (`--device optix`) to make a node without it fail its task at once, with a one-line
# error naming what exists, before anything is written. On a CPU partition drop the
# --gres line: auto falls back to the CPU.
#SBATCH --job-name=blurset
#SBATCH --gres=gpu:1
#SBATCH --cpus-per-task=4
#SBATCH --mem=16G
#SBATCH --time=24:00:00
#SBATCH --output=logs/blurset-%A_%a.out
set -euo pipefail

OUT=${OUT:-/shared/datasets/objaverse_blur}       # a filesystem every node sees
OBJECTS=${OBJECTS:-objaverse:lvis=chair+mug+shoe}  # files, folders, lists or objaverse ids
DEVICE=${DEVICE:-auto}                             # auto | optix | cuda | hip | oneapi | cpu
N=${SLURM_ARRAY_TASK_COUNT:?run as a job array}
I=${SLURM_ARRAY_TASK_ID:?run as a job array}

# Cycles kernels the driver compiles for a GPU that bpy ships none for (sm_90: H100/H200,
# 8 minutes before the first frame): one cache every node finds (docs/guide/scale.md).
export CUDA_CACHE_PATH=${CUDA_CACHE_PATH:-/shared/cache/blurset-cuda}

# The objaverse cache must be shared too, or each node downloads its own copies.
.venv/bin/blurset build --objects "$OBJECTS" --out "$OUT" \
  --objaverse-dir /shared/objaverse --objaverse-count 250 --seed 0 \
  --device "$DEVICE" --threads "${SLURM_CPUS_PER_TASK}" --shard "$I/$N" --quiet
