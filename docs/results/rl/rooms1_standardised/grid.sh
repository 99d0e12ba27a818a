#!/bin/bash
# The standardised Rooms1 grid at 10 seeds (issue 36, item 4): the five feature sets the
# verdicts read (the oracle pose, raw, sm, rec-sm, the untrained encoder), RL seed k on
# encoder seed k; encoder seeds 5-9 trained for it (COMMAND.md). An agent whose result.json
# exists is not trained again: the committed ones are kept, the rest trained.
set -e
OUT=${1:-rooms1_standardised}
RUNS=${2:-runs10}
for task in ${TASKS:-corner doorway explore}; do
  if [ $task = explore ]; then S=500000; E=125000; else S=100000; E=25000; fi
  if [ $task = doorway ]; then T=rooms2; else T=square,rooms2; fi
  /usr/bin/time -f "$task %e s wall, %U s user" nice -n 10 sensorimotor rl $task --world rooms1 \
    --features pose,raw,sm,rec-sm,random --seeds 10 --steps $S --eval-every $E \
    --eval-episodes 50 --transfer $T --workers 2 --runs $RUNS --out $OUT/$task
done
