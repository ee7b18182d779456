#!/usr/bin/env bash
# JAX compresses its persistent-cache entries with zstd where zstandard imports, else zlib:
# the whole commands with each (A: zlib, B: zstd), from the repository root of a GPU host, $OUT
# set; .whl holds the wheels the image lacks (benchmarks/fetch_gpu_runs.sh), ZSTD_WHEELS a
# zstandard wheel. The quick start on 4 pinned pairs of cores at once, get_gem on the GPU.
set -u
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/zsite ${ZSTD_WHEELS:-zstd_wheels}/*.whl
python3 -c "import zstandard" 2>/dev/null && echo "image HAS zstandard" || echo "image has no zstandard"
python3 -c "import sys; print(sys.version)"
export XLA_PYTHON_CLIENT_PREALLOCATE=false
A=/tmp/site; B=/tmp/site:/tmp/zsite
WC="python3 benchmarks/whole_command.py --tree ."
QS="train craft/make_stick --seeds 2 --env observation=compact --quiet --profile"
GEM="train craft/get_gem --seeds 10 --quiet --profile"
pair() {  # $1 pair index, $2 label, $3 path
  PYTHONPATH=$3 JAX_PLATFORMS=cpu taskset -c $((8+2*$1)),$((9+2*$1)) $WC --label $2 --cache /tmp/c_qs_$1 --runs cold warm warm --out $OUT/qs_$2_$1.jsonl -- $QS > /tmp/log_qs_$1 2>&1
}
pair 0 zlib $A & p0=$!
pair 1 zstd $B & p1=$!
pair 2 zstd $B & p2=$!
pair 3 zlib $A & p3=$!
for r in cold warm warm; do
  PYTHONPATH=$A taskset -c 0-7 $WC --label zlib --cache /tmp/c_gem_a --runs $r --out $OUT/gem_zlib.jsonl -- $GEM > /tmp/log_ga 2>&1
  PYTHONPATH=$B taskset -c 0-7 $WC --label zstd --cache /tmp/c_gem_b --runs $r --out $OUT/gem_zstd.jsonl -- $GEM > /tmp/log_gb 2>&1
done
wait $p0 $p1 $p2 $p3
tail -3 /tmp/log_ga /tmp/log_gb /tmp/log_qs_0
python3 - <<'PY'
import json, glob
import os
out = os.environ["OUT"]
for f in sorted(glob.glob(out + "/*.jsonl")):
    for line in open(f):
        r = json.loads(line)
        p = r.get("profile") or {}
        jx = p.get("jax", {})
        print(os.path.basename(f), r["kind"], round(r["whole_command_seconds"], 1), "wall", round(r.get("wall_seconds") or 0, 1),
              "compile", round(r.get("compile_seconds") or 0, 1), "final", r.get("final_success"),
              "reads", round(jx.get("jax: persistent-cache reads", {}).get("seconds", 0), 2))
PY
PYTHONPATH=$B python3 - <<'PY'
import glob, os, time, zlib, zstandard
for d, kind in (("/tmp/c_gem_a", "zlib"), ("/tmp/c_gem_b", "zstd")):
    files = [f for f in glob.glob(d + "/*-cache")]
    tot = [0, 0, 0.0]
    for f in sorted(files, key=os.path.getsize)[-6:]:
        b = open(f, "rb").read()
        t = time.perf_counter()
        raw = zlib.decompress(b) if kind == "zlib" else zstandard.ZstdDecompressor().decompress(b)
        dt = time.perf_counter() - t
        t = time.perf_counter(); zlib.compress(raw); cz = time.perf_counter() - t
        t = time.perf_counter(); zstandard.ZstdCompressor().compress(raw); cs = time.perf_counter() - t
        print(kind, os.path.basename(f)[:20], len(b), len(raw), "decomp %.3f" % dt, "zlib comp %.3f zstd comp %.3f" % (cz, cs))
    print(kind, "entries", len(files), "total bytes", sum(os.path.getsize(f) for f in files))
PY
