#!/usr/bin/env bash
# The default suite in 8 shards (shardN.txt: test files balanced by their durations on the
# 2-core machine), each on its own pair of cores at once, each shard's compiles recorded by
# compile_probe.py. From the repository root, $OUT set; .whl holds the wheels the image lacks
# (benchmarks/fetch_gpu_runs.sh). Merge: probe.json = the shards' JSON objects together.
D=benchmarks/results/test_suite_time
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
export PYTHONPATH=/tmp/site:$PWD:$PWD/$D
for i in 0 1 2 3 4 5 6 7; do
  (JAX_PLATFORMS=cpu PROBE_OUT=$OUT/probe$i.json taskset -c $((2*i)),$((2*i+1)) timeout 560 \
     python3 -m pytest -p compile_probe -p no:cacheprovider -q --durations=0 $(cat $D/shard$i.txt) \
     > $OUT/log$i.txt 2>&1) &
done
wait
