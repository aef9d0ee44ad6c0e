#!/usr/bin/env bash
# Refactor check: HEAD's release binary against a base build, taking turns.
# Usage: scripts/refcheck.sh BASE_BIN HEAD_BIN OUT_DIR   (then: python3 scripts/refsum.py OUT_DIR)
set -u
B=$1; H=$2; OUT=$3
mkdir -p "$OUT"
uptime > "$OUT/load_start.txt"
TASKS=$($H list 2>/dev/null | grep -o 'MoDe-[A-Za-z]*-[A-Za-z]*-v0' | sort -u)
for id in $TASKS; do
  for s in base head; do
    bin=$B; [ $s = head ] && bin=$H
    $bin run "$id" --policy scripted --dump-state "$OUT/dump_${s}_${id}.json" --json > "$OUT/run_${s}_${id}.json" 2>&1
  done
  if cmp -s "$OUT/dump_base_${id}.json" "$OUT/dump_head_${id}.json"; then echo "$id identical"; else echo "$id DIFFERS"; fi
done > "$OUT/experts.txt"
for round in 1 2; do
  for s in head base; do
    bin=$B; [ $s = head ] && bin=$H
    $bin bench tasks --scale 0.25 --json > "$OUT/tasks_${s}_${round}.json" 2>&1
    uptime >> "$OUT/load.txt"
  done
done
for round in 1 2 3; do
  for s in head base; do
    bin=$B; [ $s = head ] && bin=$H
    $bin bench fem --json > "$OUT/fem_${s}_${round}.json" 2>&1
    $bin bench pbd --json > "$OUT/pbd_${s}_${round}.json" 2>&1
    uptime >> "$OUT/load.txt"
  done
done
echo done > "$OUT/DONE"
