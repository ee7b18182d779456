set -u; R=$OUT
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
export MPLBACKEND=Agg SMJAX_COMPILATION_CACHE=0
P="--env observation=compact --seeds 2 --repeats 5 --parts chunk rollout update"
i=0
for t in old new old new; do tree=$PWD; [ $t = old ] && tree=$PWD/.bench/exp/t_old
  a=$((8+2*i)); JAX_PLATFORMS=cpu PYTHONPATH=$tree:/tmp/site taskset -c $a,$((a+1)) python3 $tree/benchmarks/profile_training.py $P --json $R/cpu_${t}_$i.json > $R/cpu_${t}_$i.log 2>&1 &
  i=$((i+1)); done
for t in old new; do tree=$PWD; [ $t = old ] && tree=$PWD/.bench/exp/t_old
  PYTHONPATH=$tree:/tmp/site taskset -c 0-7 python3 $tree/benchmarks/profile_training.py --seeds 10 --repeats 5 --parts chunk rollout update --json $R/gpu_$t.json > $R/gpu_$t.log 2>&1; done
wait
for f in $R/*.log; do echo "== $f"; tail -6 $f; done
