#!/usr/bin/env bash
# Long fine-tuning runs on one GPU that outlast one device call: the first call starts
# them, a later call on the same warm machine resumes them from their checkpoints.
#   bash benchmarks/long_finetune_gpu.sh "NAME TASK [train flags...]" ...
# T (default 540) seconds per call; RESUME=1 to continue. Each run's results.json lands
# in $OUT as NAME.json (its curves as NAME.csv) once finished, its log as log_NAME.txt
# (appended per call). Hosts that return only a few files from $OUT lose some of six runs'
# 18, so at the end they are packed into $OUT/runs.tgz.
set -u
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT" /tmp/runs
export XLA_PYTHON_CLIENT_MEM_FRACTION=${XLA_PYTHON_CLIENT_MEM_FRACTION:-$(python3 -c "print(round(0.9 / $#, 3))")}
pids=()
for spec in "$@"; do
  set -- $spec; name=$1; task=$2; shift 2
  again=(); [ "${RESUME:-0}" = 1 ] && again=(--resume "/tmp/runs/$name")
  ( SMJAX_CACHE_DIR=/tmp/cache_$name timeout "${T:-540}" python3 -m smjax train "$task" \
      --seeds "${SEEDS:-10}" --out "/tmp/runs/$name" --quiet "${again[@]}" "$@" >> "/tmp/runs/log_$name.txt" 2>&1
    echo "$name rc=$?"; cp "/tmp/runs/log_$name.txt" "$OUT/" 2>/dev/null
    cp "/tmp/runs/$name/results.json" "$OUT/$name.json" 2>/dev/null
    cp "/tmp/runs/$name/curves.csv" "$OUT/$name.csv" 2>/dev/null ) &
  pids+=($!)
done
for p in "${pids[@]}"; do wait "$p"; done
( cd "$OUT" && tar czf runs.tgz --remove-files $(ls *.json *.csv log_*.txt 2>/dev/null) ) 2>/dev/null
ls -la "$OUT"
