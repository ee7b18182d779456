#!/usr/bin/env bash
# `pip install -e TREE` into a new virtual environment with an empty pip cache, the trees before
# and after alternating, three rounds. /tmp/tree_old and /tmp/tree_new are clones checked out at
# the two commits (git clone REPO /tmp/tree_new; git clone REPO /tmp/tree_old; git -C
# /tmp/tree_old checkout c2bd075).
out=/tmp/install_times.jsonl; : > $out
for round in 1 2 3; do
  for label in old new; do
    rm -rf /tmp/iv /tmp/ic; python3.11 -m venv /tmp/iv
    t0=$(date +%s.%N)
    XDG_CACHE_HOME=/tmp/ic /tmp/iv/bin/pip install -q -e /tmp/tree_$label > /tmp/install_$label.log 2>&1
    rc=$?; t1=$(date +%s.%N)
    size=$(du -sm /tmp/iv | cut -f1); n=$(/tmp/iv/bin/pip list 2>/dev/null | tail -n +3 | wc -l)
    echo "{\"label\": \"$label\", \"round\": $round, \"rc\": $rc, \"seconds\": $(echo "$t1 - $t0" | bc), \"venv_mb\": $size, \"packages\": $n}" | tee -a $out
  done
done
