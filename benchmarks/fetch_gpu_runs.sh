#!/usr/bin/env bash
# Fetch sample complexity on one GPU (benchmarks/RESULTS.md, "Fetch"): the (blocks, method) runs of
# fetch_sample_complexity.py, one after another (one run alone trains ~11k env steps/s on an H100;
# two sharing the GPU get ~4k each). JOBS picks runs (default "fl3 td3 fl4 td4"), EXTRA adds flags.
# Runs from the repository root on any GPU host with smjax's dependencies (MuJoCo MJX, Brax).
# Optional: a .whl folder of wheels is installed into /tmp/site first (for a host without those
# packages and without network; download them elsewhere, py 3.12, ~34 MB, with
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
#     --platform manylinux2014_x86_64 --platform manylinux1_x86_64 -d .whl mujoco==4.0.0 mujoco-core==4.0.0 \
#     mujoco-studio==4.0.0 mujoco-mjx==3.17.0 brax==0.14.2 glfw pyopengl trimesh tensorboardx jaxopt \
#     ml-collections websockets flask flask-cors itsdangerous blinker
# ).
#
# MODE=run trains in the foreground, resuming checkpointed runs under runs/gpu (T: time limit per
# run, seconds). MODE=start detaches the queue (setsid), so it goes on after the shell that started
# it ends; MODE=status (the default) shows progress. With OUT set (optional), start and status also
# pack the results, logs and tables into $OUT/fetch_runs.tgz.
#
# Moving a run to another machine (a 4-block top-down run takes ~35 min): runs here checkpoint only
# at level boundaries (checkpoint_every=1e9), where the checkpoint holds the next level's empty
# replay buffer and is small (a few MB; ~26 MiB at 128 environments). MODE=status HOP=1 with OUT set also
# writes each job's latest checkpoint to $OUT/hop.tgz.part-*; on the next machine, in the repository
# root, `cat hop.tgz.part-* | tar xzf -`, then MODE=start JOBS=td4 resumes (--resume) where the
# checkpoint left off.
R=runs/gpu
MODE=${MODE:-status}
JOBS=${JOBS:-"fl3 td3 fl4 td4"}
mkdir -p $R
OUT=${OUT:-}; HOP=${HOP:-}; EXTRA=${EXTRA:-}
if [ -n "$OUT" ]; then mkdir -p "$OUT" && OUT=$(realpath "$OUT"); fi
if [ "$MODE" != status ] && ls .whl/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit
fi
export PYTHONPATH=/tmp/site:$PWD XLA_PYTHON_CLIENT_PREALLOCATE=false PYTHONUNBUFFERED=1
export JAX_COMPILATION_CACHE_DIR=$PWD/$R/jax_cache JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS=1
train() {  # one run: $1 = name (td3, fl4, ...)
  case $1 in td*) method=top-down;; fl*) method=flat;; esac
  timeout ${T:-100000} python benchmarks/fetch_sample_complexity.py --blocks ${1: -1} --methods $method \
    --seeds 5 --num-envs 32 --flat-max-steps 600000 --progress --resume --set checkpoint_every=1e9 \
    $EXTRA --out $R/$1 >> $R/$1.log 2>&1
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
# with OUT: one archive (results, or the last checkpoint's host state while a run is unfinished,
# its table, curves and log)
for f in $JOBS; do
  [ -f $R/$f.log ] || continue
  echo "== $f"; tr '\r' '\n' < $R/$f.log | grep -v -i warp | grep -E "level|it/s|\|" | tail -3
  tr '\r' '\n' < $R/$f.log | grep -E "^\| [34]"
done
[ -n "$OUT" ] && tar czf $OUT/fetch_runs.tgz --exclude='*/jax_cache' --exclude='*/checkpoints/step-*' \
  $(ls -d $R/*/ $R/*.log 2>/dev/null | grep -v jax_cache) 2>/dev/null
if [ -n "$OUT" ] && [ -n "$HOP" ]; then
  mkdir -p /tmp/hop && rm -rf /tmp/hop/*
  for f in $JOBS; do
    for c in $R/$f/*/checkpoints; do  # latest.json and the step it names, unless a save moved it
      [ -f $c/latest.json ] || continue
      for try in 1 2 3; do
        s=$(python3 -c "import json,sys;print(json.load(open(sys.argv[1]))['path'])" $c/latest.json)
        mkdir -p /tmp/hop/$c && cp $c/latest.json /tmp/hop/$c/ && cp -r $c/$s /tmp/hop/$c/ \
          && cmp -s $c/latest.json /tmp/hop/$c/latest.json && break
        rm -rf /tmp/hop/$c
      done
    done
  done
  (cd /tmp/hop && tar cf - runs | gzip -1 | split -b 15M - $OUT/hop.tgz.part-)
  du -sh /tmp/hop/$R/*/*/checkpoints 2>/dev/null
fi
