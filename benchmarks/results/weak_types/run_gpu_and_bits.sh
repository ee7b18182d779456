#!/usr/bin/env bash
# Football before (the tree of 6112625 in .bench/exp/t_old) and after: the same numbers (curves.csv
# and results.json without times) on pinned pairs, and cold/warm whole commands on the GPU.
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
export PYTHONPATH=/tmp/site XLA_PYTHON_CLIENT_PREALLOCATE=false
FB="train football/11v11_easy --seeds 2 --num-envs 32 --max-steps 40000 --finetune off --quiet"
direct() { # pair tree out
  (cd $2 && JAX_PLATFORMS=cpu SMJAX_CACHE_DIR=/tmp/dc_$1 PYTHONPATH=$PWD:/tmp/site taskset -c $((2*$1)),$((2*$1+1)) python3 -m smjax $FB --out $3 > /tmp/dlog_$1 2>&1)
}
direct 4 $PWD/.bench/exp/t_old /tmp/fb_old & a=$!
direct 5 $PWD /tmp/fb_new & b=$!
direct 6 $PWD/.bench/exp/t_old /tmp/fb_old_b & c=$!
direct 7 $PWD /tmp/fb_new_b & d=$!
for t in old new; do
  tree=$([ $t = old ] && echo .bench/exp/t_old || echo .)
  taskset -c 0-7 python3 benchmarks/whole_command.py --label gpu_$t --tree $tree --cache /tmp/gc_$t --runs cold warm warm --out $OUT/gpu_fb_$t.jsonl -- $FB --profile > /tmp/glog_$t 2>&1
done
wait $a $b $c $d
tail -3 /tmp/dlog_4 /tmp/dlog_5
python3 - <<'PY'
import json
def load(d):
    r = json.load(open(d + "/results.json"))
    for k in ("wall_seconds", "compile_seconds", "seed_threads", "created", "smjax_version", "profile", "timeline"):
        r.pop(k, None)
    return r, open(d + "/curves.csv").read()
import difflib
for a, b in (("/tmp/fb_old", "/tmp/fb_new"), ("/tmp/fb_old_b", "/tmp/fb_new_b"), ("/tmp/fb_old", "/tmp/fb_old_b")):
    ra, ca = load(a); rb, cb = load(b)
    diff = [k for k in set(ra) | set(rb) if ra.get(k) != rb.get(k)]
    print(a, b, "results differ in:", sorted(diff), "| curves equal:", ca == cb, len(ca))
    if ca != cb:
        print("".join(list(difflib.unified_diff(ca.splitlines(1), cb.splitlines(1)))[:12]))
PY
python3 - <<'PY'
import json, glob, os
for f in sorted(glob.glob(os.environ["OUT"] + "/*.jsonl")):
    for line in open(f):
        r = json.loads(line); p = r.get("profile") or {}
        sp = {s["label"]: s for s in p.get("spans", [])}; ch = sp.get("training chunks", {})
        jx = p.get("jax", {})
        print(os.path.basename(f), r["kind"], round(r["whole_command_seconds"], 1), "chunks", ch.get("count"), round(ch.get("seconds", 0), 2),
              "compile", round(r.get("compile_seconds") or 0, 1), "misses", jx.get("persistent-cache misses", {}).get("count"), "final", r.get("final_success"))
PY
