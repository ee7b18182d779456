# Fetch sample complexity on one GPU (benchmarks/RESULTS.md section 7): the (blocks, method)
# runs of fetch_sample_complexity.py, one after another (one run alone trains ~11k env
# steps/s on an H100; two sharing the GPU get ~4k each). JOBS picks runs (default
# "fl3 td3 fl4 td4"), EXTRA adds flags. Needs the mujoco/mjx/brax wheels in .whl (device README).
#
# A device call lasts at most 10 minutes but a machine stays up to 30: the first call
# (MODE=start) detaches the queue with setsid so it runs on between calls; later calls
# (MODE=status) show progress and copy results to $OUT. MODE=run trains in the
# foreground, resuming checkpointed runs under runs/gpu (T: time limit per run, seconds).
R=runs/gpu
MODE=${MODE:-status}
JOBS=${JOBS:-"fl3 td3 fl4 td4"}
mkdir -p $R
if [ "$MODE" != status ]; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit
fi
export PYTHONPATH=/tmp/site:$PWD XLA_PYTHON_CLIENT_PREALLOCATE=false PYTHONUNBUFFERED=1
export JAX_COMPILATION_CACHE_DIR=$PWD/$R/jax_cache JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS=1
train() {  # one run: $1 = name (td3, fl4, ...)
  case $1 in td*) method=top-down;; fl*) method=flat;; esac
  timeout ${T:-100000} python benchmarks/fetch_sample_complexity.py --blocks ${1: -1} --methods $method \
    --seeds 5 --num-envs 32 --flat-max-steps 600000 --progress --resume $EXTRA --out $R/$1 >> $R/$1.log 2>&1
  echo "$1 exit $? $(date +%T)" >> $R/queue.log
}
case $MODE in
  start) nvidia-smi --query-gpu=name --format=csv,noheader
         export -f train; export R T EXTRA
         setsid bash -c "for j in $JOBS; do train \$j; done; echo queue done >> $R/queue.log" \
           > /dev/null 2>&1 < /dev/null &
         sleep ${WAIT:-0};;
  run)   for j in $JOBS; do train $j; done;;
esac
cat $R/queue.log 2>/dev/null
# $OUT takes few files: everything goes back in one archive (results, or the last checkpoint's
# host state while a run is unfinished, its table, curves and log)
for f in $JOBS; do
  [ -f $R/$f.log ] || continue
  echo "== $f"; tr '\r' '\n' < $R/$f.log | grep -v -i warp | grep -E "level|it/s|\|" | tail -3
  tr '\r' '\n' < $R/$f.log | grep -E "^\| [34]"
done
[ -n "$OUT" ] && tar czf $OUT/fetch_runs.tgz --exclude='*/jax_cache' --exclude='*/checkpoints/step-*' \
  $(ls -d $R/*/ $R/*.log 2>/dev/null | grep -v jax_cache) 2>/dev/null
