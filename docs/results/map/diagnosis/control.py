"""Controls without a map: the random behaviour and a constant moving action (1 right, 2 straight,
3 left; the reflex kept) over 200 start/goal pairs, as planning.run_episode scores them.
Argument: WORLD; DATA as in context.py."""

import math
import os
import sys

import numpy as np

from sensorimotor.analysis.map.planning import BUDGET, GOAL_RADIUS, _command
from sensorimotor.sim.core import TURN_THRESHOLD, apply_motor, behaviour, read_sensors, sample_start
from sensorimotor.sim.database import load_database

db = load_database(f"{os.environ.get('DATA', 'data')}/{sys.argv[1]}.npz")
world, layout = db.world, db.layout


def episode(goal, start, rng, policy):
    x, y, h = start
    for t in range(BUDGET + 1):
        if math.hypot(x - goal[0], y - goal[1]) <= GOAL_RADIUS:
            return 1
        if t == BUDGET:
            return 0
        r = read_sensors(world, np.array([x, y, h]), layout)[0]
        if policy == "random" or r.min() < TURN_THRESHOLD:
            d, rr = behaviour(r.min(), rng.random(), rng.random())
        else:
            d, rr = _command(policy, rng)
        x, y, h = apply_motor(x, y, h, d, rr)


rng = np.random.default_rng(0)
res = {p: [] for p in ("random", 1, 2, 3)}
for _i in range(200):
    goal = np.array(sample_start(world, rng)[:2])
    start = sample_start(world, rng)
    for p in res:
        res[p].append(episode(goal, start, np.random.default_rng(rng.integers(2**32)), p))
print(sys.argv[1], {p: np.mean(v) for p, v in res.items()})
