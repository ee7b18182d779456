# Fetch sample complexity on one GPU (benchmarks/RESULTS.md section 7): the four (blocks,
# method) runs of fetch_sample_complexity.py side by side, resumable (each call continues the
# checkpointed runs under runs/gpu). JOBS picks runs (default "td3 fl3 td4 fl4"), T the
# per-call time limit in seconds, EXTRA more flags. Needs the mujoco/mjx/brax wheels in .whl (device README).
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl && export PYTHONPATH=/tmp/site:$PWD || exit
export XLA_PYTHON_CLIENT_PREALLOCATE=false PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name --format=csv,noheader
B=benchmarks/fetch_sample_complexity.py
R=runs/gpu
mkdir -p $R
T=${T:-560}
JOBS=${JOBS:-"td3 fl3 td4 fl4"}
for name in $JOBS; do
  case $name in td*) method=top-down;; fl*) method=flat;; esac
  set -- $name ${name: -1} $method
  timeout $T python $B --blocks $2 --methods $3 --seeds 5 --num-envs 32 --flat-max-steps 600000 --progress --resume $EXTRA --out $R/$1 >> $R/$1.log 2>&1 &
done
wait
for f in $JOBS; do
  mkdir -p $OUT/$f; cp $R/$f/table.md $R/$f/summary.json $R/$f/*.png $OUT/$f/ 2>/dev/null
  # results when finished; else the host state of the last checkpoint (levels done, curves)
  for d in $R/$f/stack*; do [ -d $d ] && mkdir -p $OUT/$f/$(basename $d) && cp $d/results.json $d/curves.csv $d/checkpoints/latest.json $OUT/$f/$(basename $d)/ 2>/dev/null; done
  echo "== $f"; tr '\r' '\n' < $R/$f.log | grep -v -i warp | grep -E "level|it/s|\|" | awk 'NR%15==0' | tail -8; tr '\r' '\n' < $R/$f.log | grep -E "^\| [34]"
done
