#!/usr/bin/env bash
# The quick start, the tree before (c2bd075) and after (in .bench/exp/t_old, t_new: git archive), 4 pinned pairs per tree at once: cold, warm, warm
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site MPLBACKEND=Agg JAX_PLATFORMS=cpu
{ lscpu | grep "Model name"; python3 -c "import jax; print(jax.__version__)"; } > $OUT/machine.txt
for i in 0 1 2 3 4 5 6 7; do
  if [ $((i % 2)) -eq 0 ]; then t=old; else t=new; fi
  taskset -c $((2*i)),$((2*i+1)) python3 benchmarks/whole_command.py --label $t --tree .bench/exp/t_$t \
    --cache /tmp/c$i --runs cold warm warm --out $OUT/qs_pair$i.jsonl -- \
    train craft/make_stick --seeds 2 --env observation=compact --profile > $OUT/log$i.txt 2>&1 &
done
wait
cat $OUT/qs_pair*.jsonl | python3 -c "
import json,sys
for l in sys.stdin:
    d=json.loads(l); print(d.get('kind'), round(d['whole_command_seconds'],1), d.get('wall_seconds') and round(d['wall_seconds'],1), d.get('compile_seconds') and round(d['compile_seconds'],1), d.get('final_success'), d.get('episodes_to_threshold'), d.get('returncode'))
"
