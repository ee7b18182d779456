#!/usr/bin/env bash
# Football on 2 pinned cores: seed groups on threads (the default) against one program for
# both seeds (SMJAX_SEED_THREADS=1), the current tree, cold then warm twice, 4 pairs each.
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
export PYTHONPATH=/tmp/site JAX_PLATFORMS=cpu
FB="train football/11v11_easy --seeds 2 --num-envs 32 --max-steps 80000 --finetune off --quiet --profile"
for i in 0 1 2 3 4 5 6 7; do
  t=$([ $i -lt 4 ] && echo 2 || echo 1)
  SMJAX_SEED_THREADS=$t taskset -c $((2*i)),$((2*i+1)) python3 benchmarks/whole_command.py --label threads$t --tree . --cache /tmp/c3_$i --runs cold warm warm --out $OUT/threads${t}_$i.jsonl -- $FB > /tmp/l3_$i 2>&1 &
done
wait
python3 - <<'PY'
import json, glob, os
for f in sorted(glob.glob(os.environ["OUT"] + "/*.jsonl")):
    for line in open(f):
        r = json.loads(line); p = r.get("profile") or {}
        sp = {s["label"]: s for s in p.get("spans", [])}; ch = sp.get("training chunks", {})
        print(os.path.basename(f), r["kind"], round(r["whole_command_seconds"], 1), "chunks", ch.get("count"), round(ch.get("seconds", 0), 2),
              "compile", round(r.get("compile_seconds") or 0, 1), "final", r.get("final_success"))
PY
