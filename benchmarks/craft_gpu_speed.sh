#!/usr/bin/env bash
# Whole-command wall time of Craft training on one GPU, this tree against a baseline tree, with a
# cold and a warm JAX compilation cache. Run from the repository root on any GPU host with smjax's
# dependencies installed; put the baseline's `smjax` package in $BASE/smjax (e.g.
# `git worktree add /tmp/base <commit> && mkdir -p .base && cp -r /tmp/base/smjax .base/`).
#   RUNS="new_cold new_warm base new_set_frozen_eval=all" TASK=craft/get_gem EXTRA="" \
#     bash benchmarks/craft_gpu_speed.sh
# (new_set_FIELD=VALUE: this tree with --set FIELD=VALUE, warm cache)
# Each run's results.json lands in $OUT (default runs/craft_gpu_speed) as NAME.json, its `time`
# line in $OUT/log.txt. Optional: where mujoco is not importable and a .whl folder holds wheels,
# they are installed into /tmp/site first (Craft itself needs none of them).
set -u
OUT=${OUT:-runs/craft_gpu_speed}; BASE=${BASE:-.base}; TASK=${TASK:-craft/get_gem}; SEEDS=${SEEDS:-10}
EXTRA=${EXTRA:-}; RUNS=${RUNS:-"new_cold new_warm base"}
mkdir -p "$OUT" /tmp/runs
if ! python3 -c "import mujoco" 2>/dev/null && ls .whl/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site${PYTHONPATH:+:$PYTHONPATH}
fi
OUT=$(realpath -m "$OUT")
root=$(pwd)
one() {  # NAME DIR CACHE_DIR
  local name=$1 dir=$2 cache=$3
  rm -rf "/tmp/runs/$name"
  ( cd "$dir" && SMJAX_CACHE_DIR=$cache /usr/bin/time -f "$name wall %e s" \
      python3 -m smjax train "$TASK" --seeds "$SEEDS" --out "/tmp/runs/$name" --quiet $EXTRA ) \
      >> "$OUT/log.txt" 2>&1
  cp "/tmp/runs/$name/results.json" "$OUT/${name//=/-}.json" 2>/dev/null
  tail -n 1 "$OUT/log.txt"
}
for r in $RUNS; do
  case $r in
    new_cold) rm -rf /tmp/cache_new; one new_cold "$root" /tmp/cache_new ;;
    new_warm) one new_warm "$root" /tmp/cache_new ;;
    base) one base "$BASE" /tmp/cache_base ;;
    new_set_*) EXTRA="$EXTRA --set ${r#new_set_}" one "$r" "$root" /tmp/cache_new ;;
    *) echo "unknown run $r" ;;
  esac
done
