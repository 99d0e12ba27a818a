#!/bin/bash
# The full Rooms1 grid: three tasks, seven feature sets, 5 seeds, transfer.
set -e
OUT=${1:-rooms1_full}
for task in explore corner doorway; do
  if [ $task = explore ]; then S=500000; E=125000; else S=100000; E=25000; fi
  if [ $task = doorway ]; then T=rooms2; else T=square,rooms2; fi
  /usr/bin/time -f "$task %e s wall, %U s user" nice -n 5 sensorimotor rl $task --world rooms1 \
    --features pose,raw,s,sm,rec-s,rec-sm,random --seeds 5 --steps $S \
    --eval-every $E --eval-episodes 50 --transfer $T --workers 2 \
    --runs docs/results/runs --out $OUT/$task
done
