#!/usr/bin/env bash
# Before (the tree of 6112625 in .bench/exp/t_old: git archive 6112625 smjax benchmarks
# pyproject.toml) and after: football (its weakly typed kick-off facing) and the craft quick
# start, whole commands on pinned pairs, cold then warm.
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
export PYTHONPATH=/tmp/site JAX_PLATFORMS=cpu
FB="train football/11v11_easy --seeds 2 --num-envs 32 --max-steps 40000 --finetune off --quiet --profile"
QS="train craft/make_stick --seeds 2 --env observation=compact --quiet --profile"
pair() { # index label tree args...
  i=$1; l=$2; t=$3; shift 3
  taskset -c $((2*i)),$((2*i+1)) timeout 560 python3 benchmarks/whole_command.py --label $l --tree $t --cache /tmp/c_$i --runs cold warm --out $OUT/$l.jsonl -- "$@" > /tmp/log_$i 2>&1
}
pair 0 fb_old .bench/exp/t_old $FB &
pair 1 fb_new . $FB &
pair 2 fb_old2 .bench/exp/t_old $FB &
pair 3 fb_new2 . $FB &
pair 4 qs_old .bench/exp/t_old $QS &
pair 5 qs_new . $QS &
pair 6 qs_old2 .bench/exp/t_old $QS &
pair 7 qs_new2 . $QS &
wait
tail -2 /tmp/log_0 /tmp/log_1
python3 - <<'PY'
import json, glob, os
for f in sorted(glob.glob(os.environ["OUT"] + "/*.jsonl")):
    for line in open(f):
        r = json.loads(line); p = r.get("profile") or {}
        sp = {s["label"]: s for s in p.get("spans", [])}
        ch = sp.get("training chunks", {})
        print(os.path.basename(f), r["kind"], round(r["whole_command_seconds"], 1), "rc", r["returncode"],
              "chunks", ch.get("count"), round(ch.get("seconds", 0), 1), "compile", round(r.get("compile_seconds") or 0, 1),
              "final", r.get("final_success"), "eps", r.get("episodes_to_threshold"))
PY
