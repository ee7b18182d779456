#!/usr/bin/env bash
# Environment throughput on an accelerator (benchmarks/RESULTS.md, "Environment throughput"): one
# JSON line per configuration, appended to $OUT/bench.jsonl (default OUT=runs/gpu_bench).
# Usage: [OUT=dir] [WHAT=craft|football|fetch|all] bash benchmarks/gpu_bench.sh
set -u
OUT=${OUT:-runs/gpu_bench}; mkdir -p "$OUT"; WHAT=${WHAT:-all}
log() { tee -a "$OUT/bench.jsonl"; }
python3 -c "import smjax, jax; print(jax.__version__, jax.devices())"
if [ "$WHAT" = all ] || [ "$WHAT" = craft ]; then
  for obs in paper none compact; do for n in 1 64 1024 4096 16384; do
    python3 -m smjax bench craft/get_gem --num-envs $n --steps 200 --env observation=$obs 2>/dev/null | log
  done; done
fi
if [ "$WHAT" = all ] || [ "$WHAT" = football ]; then
  for n in 1 64 1024 8192; do python3 -m smjax bench football/11v11_hard --num-envs $n --steps 200 2>/dev/null | log; done
fi
if [ "$WHAT" = all ] || [ "$WHAT" = fetch ]; then
  for n in 1 64 1024 8192; do python3 -m smjax bench fetch/stack3 --num-envs $n --steps 20 2>/dev/null | log; done
fi
