set -u; R=$OUT
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
export PYTHONPATH=/tmp/site MPLBACKEND=Agg
W="python3 benchmarks/whole_command.py"
G="train craft/get_gem --seeds 10 --env observation=compact --quiet --profile"
JAX_PLATFORMS=cpu taskset -c 8,9 timeout 570 $W --label old --tree .bench/exp/t_old --cache /tmp/c1 --runs cold --out $R/gem_old.jsonl -- $G > /dev/null 2>&1 &
JAX_PLATFORMS=cpu taskset -c 10,11 timeout 570 $W --label new --tree . --cache /tmp/c2 --runs cold --out $R/gem_new.jsonl -- $G > /dev/null 2>&1 &
Q="train craft/make_stick --seeds 2 --env observation=compact --quiet --profile"
JAX_PLATFORMS=cpu taskset -c 12,13 timeout 570 $W --label old --tree .bench/exp/t_old --cache /tmp/c3 --runs cold warm warm --out $R/qs_old.jsonl -- $Q > /dev/null 2>&1 &
JAX_PLATFORMS=cpu taskset -c 14,15 timeout 570 $W --label new --tree . --cache /tmp/c4 --runs cold warm warm --out $R/qs_new.jsonl -- $Q > /dev/null 2>&1 &
if python3 -c "import pytest, hypothesis" 2>/dev/null; then
  JAX_PLATFORMS=cpu taskset -c 0-7 timeout 500 python3 -m pytest -q -p no:cacheprovider tests/test_seed_threads.py tests/test_tick_costs.py tests/test_per_seed_levels.py 2>&1 | tail -15
else echo "no pytest here"; fi
wait
python3 - <<'P'
import json,glob,os
for f in sorted(glob.glob(os.environ['OUT']+'/*.jsonl')):
    for l in open(f):
        d=json.loads(l); fs=d.get('final_success') or [0]
        print(os.path.basename(f), d['label'], d['kind'], round(d['whole_command_seconds'],1), d.get('wall_seconds') and round(d['wall_seconds'],1), round(sum(fs)/len(fs),4), round(min(fs),4), d.get('episodes_to_threshold'))
P
