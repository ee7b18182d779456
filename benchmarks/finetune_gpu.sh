#!/usr/bin/env bash
# Fine-tuning runs on one GPU, several at once, from the repository root on any GPU host:
#   bash benchmarks/finetune_gpu.sh "NAME TASK [train flags...]" "NAME2 TASK2 ..." ...
# Each run's results.json and curves.csv land in $OUT (default runs/finetune_gpu) as NAME.json /
# NAME.csv, its log (with a `time` line) as log_NAME.txt. SEEDS (default 10) seeds per run.
# Optional: where mujoco is not importable and a .whl folder holds wheels, they are installed into
# /tmp/site first (Fetch needs them; Craft and football do not).
set -u
OUT=${OUT:-runs/finetune_gpu}; mkdir -p "$OUT" /tmp/runs
if ls .whl/*.whl >/dev/null 2>&1 && ! python3 -c "import mujoco" 2>/dev/null; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site${PYTHONPATH:+:$PYTHONPATH}
fi
# runs share the GPU: each takes a slice of its memory instead of XLA's default 75%
export XLA_PYTHON_CLIENT_MEM_FRACTION=${XLA_PYTHON_CLIENT_MEM_FRACTION:-$(python3 -c "print(round(0.9 / $#, 3))")}
pids=()
for spec in "$@"; do
  set -- $spec; name=$1; task=$2; shift 2
  ( rm -rf "/tmp/runs/$name"
    SMJAX_CACHE_DIR=/tmp/cache_$name /usr/bin/time -f "$name wall %e s" python3 -m smjax train \
      "$task" --seeds "${SEEDS:-10}" --out "/tmp/runs/$name" --quiet "$@" > "$OUT/log_$name.txt" 2>&1
    cp "/tmp/runs/$name/results.json" "$OUT/$name.json"; cp "/tmp/runs/$name/curves.csv" "$OUT/$name.csv"
    tail -n 1 "$OUT/log_$name.txt" ) &
  pids+=($!)
done
for p in "${pids[@]}"; do wait "$p"; done
