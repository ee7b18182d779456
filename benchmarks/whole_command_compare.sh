#!/usr/bin/env bash
# Two smjax trees side by side on one many-core host, whole commands, empty and warm caches:
#   - the README quick start on 2 CPU cores each (taskset pairs: REPEATS per tree, all at once);
#   - craft/get_gem with 10 seeds on the GPU (old cold, new cold, old warm, new warm), on the
#     cores left over, beside the CPU runs.
# Usage: OLD=path/to/old/tree NEW=. bash benchmarks/whole_command_compare.sh [RESULTS_DIR]
# (an old tree: mkdir -p old && git archive COMMIT smjax pyproject.toml | tar x -C old)
set -u
OLD=${OLD:?name the old tree}; NEW=${NEW:-.}; R=${1:-runs/whole_command}; REPEATS=${REPEATS:-3}
GPU=${GPU:-1}; mkdir -p $R
QUICK="train craft/make_stick --seeds 2 --env observation=compact --quiet"
pair=0
for label in old new; do
  tree=$OLD; [ $label = new ] && tree=$NEW
  for i in $(seq 1 $REPEATS); do
    c0=$((2 * pair)); c1=$((2 * pair + 1)); pair=$((pair + 1))
    JAX_PLATFORMS=cpu taskset -c $c0,$c1 python3 benchmarks/whole_command.py --label $label \
      --tree $tree --cache /tmp/wc_cpu_${label}_$i --out $R/quickstart_cpu.jsonl -- $QUICK \
      > $R/quickstart_${label}_$i.log 2>&1 &
  done
done
if [ "$GPU" = 1 ]; then
  rest=$((2 * pair))-$(($(nproc) - 1))
  for kind in cold warm; do
    for label in old new; do
      tree=$OLD; [ $label = new ] && tree=$NEW
      taskset -c $rest python3 benchmarks/whole_command.py --label $label --tree $tree \
        --cache /tmp/wc_gpu_$label --runs $kind --out $R/get_gem_gpu.jsonl -- \
        train craft/get_gem --seeds 10 --quiet >> $R/get_gem_gpu.log 2>&1
    done
  done
fi
wait
cat $R/*.log
