set -u; R=$OUT
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
export PYTHONPATH=/tmp/site MPLBACKEND=Agg
{ lscpu | grep "Model name"; nvidia-smi -L; } > $R/machine.txt 2>&1
W="python3 benchmarks/whole_command.py"
Q="train craft/make_stick --seeds 2 --env observation=compact --quiet --profile"
pair() { # cores label tree cache
  JAX_PLATFORMS=cpu taskset -c $1 $W --label $2 --tree $3 --cache $4 --runs cold --out $R/cpu_quickstart_$5.jsonl -- $Q > /dev/null 2>&1
  for i in 1 2; do JAX_PLATFORMS=cpu taskset -c $1 $W --label $2-edited --tree $3 --cache $4 --runs warm --out $R/cpu_quickstart_$5.jsonl -- $Q --set finetune_max_episodes=1900$i --max-episodes 3900$i > /dev/null 2>&1; done
}
pair 8,9 old .bench/exp/t_old /tmp/q_old1 a & pair 10,11 new . /tmp/q_new1 b & pair 12,13 old .bench/exp/t_old /tmp/q_old2 c & pair 14,15 new . /tmp/q_new2 d &
G="train craft/get_gem --seeds 10 --quiet --profile"
for t in old new; do tree=.; [ $t = old ] && tree=.bench/exp/t_old
  taskset -c 0-7 timeout 200 $W --label $t --tree $tree --cache /tmp/g_$t --runs cold --out $R/gpu_get_gem.jsonl -- $G > /dev/null 2>&1; done
for i in 1 2; do for t in old new; do tree=.; [ $t = old ] && tree=.bench/exp/t_old
  taskset -c 0-7 timeout 120 $W --label $t-edited --tree $tree --cache /tmp/g_$t --runs warm --out $R/gpu_get_gem.jsonl -- $G --set finetune_max_episodes=1900$i --max-episodes 3900$i > /dev/null 2>&1; done; done
wait
python3 - <<'P'
import json,glob,os
for f in sorted(glob.glob(os.environ['OUT']+'/*.jsonl')):
    for l in open(f):
        d=json.loads(l); print(os.path.basename(f), d['label'], d['kind'], round(d['whole_command_seconds'],1), d.get('wall_seconds') and round(d['wall_seconds'],1), d.get('compile_seconds') and round(d['compile_seconds'],1), d.get('final_success') and [round(x,4) for x in d['final_success']][:10], d.get('episodes_to_threshold'))
P
