#!/usr/bin/env bash
# Fetch stack4 on one GPU with the command a user types (configs/fetch_stack4.yaml): the top-down
# run (td) and the flat baseline at the same settings (flat), one after the other, each resumed
# from its checkpoint when one is there. Runs from the repository root on any GPU host with smjax's
# dependencies (MuJoCo MJX). T (default 540) bounds the seconds of one invocation: a run still
# going is interrupted with SIGINT and keeps its last checkpoint (written every CKPT seconds,
# default 120); invoke again with the same JOBS to go on. To go on on another machine, copy
# runs/gpu4 there (or unpack the hop archive below: `cat hop.tgz.part-* | tar xzf -`).
# Optional: a .whl folder of wheels (benchmarks/fetch_gpu_runs.sh lists them) is installed into
# /tmp/site first; with OUT set, $OUT/results.tgz (results and logs) and $OUT/hop.tgz.part-*
# (runs/gpu4 with its checkpoints, in 15 MB parts) are written at the end.
R=runs/gpu4
JOBS=${JOBS:-"td flat"}
CKPT=${CKPT:-120}
mkdir -p $R
OUT=${OUT:-}
if [ -n "$OUT" ]; then mkdir -p "$OUT" && OUT=$(realpath "$OUT"); fi
if ls .whl/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site \
    .whl/*.whl 2>/dev/null || exit
fi
export PYTHONPATH=/tmp/site:$PWD XLA_PYTHON_CLIENT_PREALLOCATE=false PYTHONUNBUFFERED=1
export JAX_COMPILATION_CACHE_DIR=$PWD/$R/jax_cache
nvidia-smi --query-gpu=name --format=csv,noheader
start=$(date +%s)
for job in $JOBS; do
  case $job in
    td)   extra=();;
    flat) extra=(--method flat --set 'levels={}' --max-steps ${FLAT_STEPS:-1200000});;
  esac
  if [ -f $R/$job/results.json ]; then echo "$job done"; continue; fi
  if [ -f $R/$job/checkpoints/latest.json ]; then where=(--resume $R/$job); else where=(--out $R/$job); fi
  left=$(( ${T:-540} - ($(date +%s) - start) ))
  [ $left -gt 60 ] || break
  timeout -s INT $left python -m smjax train fetch/stack4 --seeds 5 --config configs/fetch_stack4.yaml \
    --env obs_include_goals=true --set checkpoint_every=$CKPT "${extra[@]}" "${where[@]}" \
    >> $R/$job.log 2>&1
  echo "$job exit $? after $(( $(date +%s) - start )) s" | tee -a $R/queue.log
done
for job in $JOBS; do echo "== $job"; tr '\r' '\n' < $R/$job.log 2>/dev/null | grep -v -i warp | tail -4; done
# with OUT: results and logs, and each unfinished run's latest checkpoint in 15 MB parts
if [ -n "$OUT" ]; then
  tar czf $OUT/results.tgz --exclude='jax_cache' --exclude='checkpoints' $R 2>/dev/null
  (tar cf - --exclude='jax_cache' $R | gzip -1 | split -b 15M - $OUT/hop.tgz.part-) 2>/dev/null
  ls -la $OUT
fi
