#!/usr/bin/env bash
# Long fine-tuning runs on one GPU, several at once, in invocations of at most T seconds (default
# 540): the first starts them, a later one on the same machine (RESUME=1) resumes them from their
# checkpoints under /tmp/runs. From the repository root on any GPU host:
#   bash benchmarks/long_finetune_gpu.sh "NAME TASK [train flags...]" ...
# Each run's results.json lands in $OUT (default runs/long_finetune_gpu) as NAME.json (its curves
# as NAME.csv) once finished, its log as log_NAME.txt (appended per invocation); at the end they
# are packed into one archive, $OUT/runs.tgz.
set -u
OUT=${OUT:-runs/long_finetune_gpu}; mkdir -p "$OUT" /tmp/runs
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
