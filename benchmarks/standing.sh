#!/usr/bin/env bash
# Where the whole commands stand, the current tree on one GPU host with 16 cores, in one go:
#   cores 0-7 and the GPU: craft/get_gem with 10 seeds (cold, then warm) and 100 seeds (cold);
#   pinned CPU pairs beside it: get_gem and get_gold with 10 seeds (compact, cold) and the
#   README quick start (cold, warm, warm), each a faithful 2-core figure.
# Usage: OUT=DIR bash benchmarks/standing.sh   (wheels the host lacks in .whl/, as
# benchmarks/fetch_gpu_runs.sh lists them; each run is cut at its timeout)
set -u
R=${OUT:?name a results folder}; mkdir -p $R
if ls .whl/*.whl > /dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl
  export PYTHONPATH=/tmp/site:$PWD
fi
export MPLBACKEND=Agg
{ lscpu | grep "Model name"; nvidia-smi -L; } > $R/machine.txt 2>&1
W="python3 benchmarks/whole_command.py --tree . --label now"
CPU="--env observation=compact --quiet --profile"
JAX_PLATFORMS=cpu taskset -c 8,9 timeout 560 $W --cache /tmp/c_gem --runs cold \
  --out $R/cpu_10_seeds.jsonl -- train craft/get_gem --seeds 10 $CPU > $R/cpu_gem.log 2>&1 &
JAX_PLATFORMS=cpu taskset -c 10,11 timeout 560 $W --cache /tmp/c_gold --runs cold \
  --out $R/cpu_10_seeds.jsonl -- train craft/get_gold --seeds 10 $CPU > $R/cpu_gold.log 2>&1 &
JAX_PLATFORMS=cpu taskset -c 12,13 timeout 560 $W --cache /tmp/c_qs --runs cold warm warm \
  --out $R/cpu_quickstart.jsonl -- train craft/make_stick --seeds 2 $CPU > $R/cpu_qs.log 2>&1 &
taskset -c 0-7 timeout 560 $W --cache /tmp/g10 --runs cold warm --out $R/gpu_get_gem.jsonl -- \
  train craft/get_gem --seeds 10 --quiet --profile > $R/gpu_10.log 2>&1
taskset -c 0-7 timeout 400 $W --cache /tmp/g100 --runs cold --out $R/gpu_get_gem.jsonl -- \
  train craft/get_gem --seeds 100 --quiet --profile > $R/gpu_100.log 2>&1
wait
cut -c1-300 $R/*.jsonl
