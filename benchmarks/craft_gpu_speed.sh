#!/usr/bin/env bash
# Whole-command wall time of Craft training on one GPU, this tree against a baseline tree,
# with a cold and a warm JAX compilation cache. Run from the repository root on the GPU
# machine (the device tool), with the GPU image's missing wheels in .whl (see
# fetch_gpu_runs.sh for the download command) and the baseline's `smjax` package copied to
# $BASE/smjax (e.g. `git worktree add /tmp/base <commit> && cp -r /tmp/base/smjax .base/`).
#   RUNS="new_cold new_warm base new_set_frozen_eval=all" TASK=craft/get_gem EXTRA="" \
#     bash benchmarks/craft_gpu_speed.sh
# (new_set_FIELD=VALUE: this tree with --set FIELD=VALUE, warm cache)
# Each run's results.json lands in $OUT as NAME.json, its `time` line in $OUT/log.txt.
set -u
OUT=${OUT:-/tmp/out}; BASE=${BASE:-.base}; TASK=${TASK:-craft/get_gem}; SEEDS=${SEEDS:-10}
EXTRA=${EXTRA:-}; RUNS=${RUNS:-"new_cold new_warm base"}
mkdir -p "$OUT" /tmp/runs
if ! python3 -c "import mujoco" 2>/dev/null; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site
fi
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
