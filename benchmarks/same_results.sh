#!/usr/bin/env bash
# Does a change move results? Two smjax trees train the same four runs (the README quick start,
# get_gold with 2 seeds, a Fetch and a football smoke run), each pinned to 2 CPU cores, all
# side by side (16 cores), then every field of the two results.json files is compared.
# Usage: OLD=path/to/old/tree NEW=. bash benchmarks/same_results.sh [RESULTS_DIR]
# (an old tree: mkdir -p old && git archive COMMIT smjax pyproject.toml | tar x -C old)
set -u
OLD=${OLD:?name the old tree}; NEW=${NEW:-.}; R=$(realpath -m ${1:-runs/same_results}); mkdir -p $R
OLD=$(realpath $OLD); NEW=$(realpath $NEW)
SMALL="--set success_window=32 --set gate_envs=16 --set eval_envs=16 --set finetune_max_episodes=32"
declare -A CMD=(
  [quickstart]="craft/make_stick --seeds 2 --env observation=compact"
  [get_gold]="craft/get_gold --seeds 2"
  [fetch]="fetch/stack1 --seeds 1 --algo dqn --num-envs 16 --max-episodes 64 $SMALL --set eval_max_ticks=200 --set gate_max_ticks=200"
  [football]="football/11v11_easy --seeds 1 --num-envs 16 --max-episodes 64 --env game_length=200 $SMALL --set eval_max_ticks=400 --set gate_max_ticks=400")
pair=0
for w in "${!CMD[@]}"; do
  for label in old new; do
    tree=$OLD; [ $label = new ] && tree=$NEW
    c0=$((2 * pair)); c1=$((2 * pair + 1)); pair=$((pair + 1))
    (cd $R && SMJAX_CACHE_DIR=$R/cache_${w}_$label JAX_PLATFORMS=cpu MPLBACKEND=Agg \
      PYTHONPATH=$tree${PYTHONPATH:+:$PYTHONPATH} taskset -c $c0,$c1 \
      python3 -m smjax train ${CMD[$w]} --out $R/${w}_$label --quiet > $R/${w}_$label.log 2>&1) &
  done
done
wait
python3 - "$R" "${!CMD[@]}" <<'PY'
import json, sys
root, names = sys.argv[1], sys.argv[2:]
for w in names:
    old, new = (json.load(open(f"{root}/{w}_{t}/results.json")) for t in ("old", "new"))
    moved = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
    print(f"{w}: fields that differ: {moved or 'none'}; final_success {new['final_success']}")
PY
