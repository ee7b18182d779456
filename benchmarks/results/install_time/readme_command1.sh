#!/usr/bin/env bash
# The README's first command as a new user types it, the tree before (c2bd075) and after in
# turn: a fresh clone of REPO, a new virtual environment, empty pip and compile caches.
# Usage: REPO=PATH_OR_URL bash readme_command1.sh   (appends to /tmp/cmd1_pair.jsonl)
REPO=${REPO:?name the repository to clone}
out=/tmp/cmd1_pair.jsonl; : > $out
for label in old new new old; do
  rm -rf /tmp/c1 /tmp/c1cache; git clone -q "$REPO" /tmp/c1
  if [ $label = old ]; then git -C /tmp/c1 checkout -q c2bd075; fi
  cd /tmp/c1; python3.11 -m venv .venv; . .venv/bin/activate
  export XDG_CACHE_HOME=/tmp/c1cache
  t0=$(date +%s.%N)
  pip install -q -e . > /tmp/c1_pip_$label.log 2>&1
  t1=$(date +%s.%N)
  python -m smjax train craft/make_stick --seeds 2 --env observation=compact --out runs/quickstart > /tmp/c1_run_$label.log 2>&1
  rc=$?; t2=$(date +%s.%N)
  deactivate; cd /
  echo "{\"label\": \"$label\", \"rc\": $rc, \"install_s\": $(echo "$t1 - $t0" | bc), \"train_s\": $(echo "$t2 - $t1" | bc), \"whole_s\": $(echo "$t2 - $t0" | bc), \"results\": $(python3 -c "import json; d=json.load(open('/tmp/c1/runs/quickstart/results.json')); print(json.dumps({k: d[k] for k in ('final_success','episodes_to_threshold','wall_seconds','compile_seconds')}))")}" >> $out
done
