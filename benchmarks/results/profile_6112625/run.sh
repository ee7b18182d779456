#!/usr/bin/env bash
# profile_training, the tree before (6112625 in .bench/exp/t_old: git archive) and after, side by side:
# 4 pinned pairs per task at once (craft get_gem compact, football), the trees alternating,
# then get_gem with 10 seeds on the GPU, one tree after the other.
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
export SMJAX_COMPILATION_CACHE=0; mkdir -p /tmp/p
prof() { # pair tree label args...
  i=$1; t=$2; l=$3; shift 3
  (cd $t && PYTHONPATH=$PWD:/tmp/site JAX_PLATFORMS=cpu taskset -c $((2*i)),$((2*i+1)) python3 benchmarks/profile_training.py "$@" > /tmp/p/$l.txt 2>&1)
}
QS="--env observation=compact --seeds 2 --repeats 5 --parts chunk rollout update"
FB="--task football/11v11_easy --seeds 2 --num-envs 32 --repeats 5 --parts chunk rollout update"
prof 0 .bench/exp/t_old cpu_craft_before $QS & prof 1 $PWD cpu_craft_after $QS &
prof 2 $PWD cpu_craft_after2 $QS & prof 3 .bench/exp/t_old cpu_craft_before2 $QS &
prof 4 .bench/exp/t_old cpu_football_before $FB & prof 5 $PWD cpu_football_after $FB &
prof 6 $PWD cpu_football_after2 $FB & prof 7 .bench/exp/t_old cpu_football_before2 $FB &
wait
for t in old new; do
  tree=$([ $t = old ] && echo .bench/exp/t_old || echo $PWD)
  (cd $tree && PYTHONPATH=$PWD:/tmp/site XLA_PYTHON_CLIENT_PREALLOCATE=false python3 benchmarks/profile_training.py --seeds 10 --repeats 5 --parts chunk rollout update > /tmp/p/gpu_gem_$t.txt 2>&1)
done
for f in /tmp/p/*.txt; do echo "== $(basename $f)"; grep -E "^(chunk|rollout|update) " $f; done; for f in /tmp/p/*.txt; do echo "== $(basename $f)"; cat $f; done > $OUT/profile_all.txt
