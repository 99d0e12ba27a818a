"""What `homing` asks of a memory: a scripted driver on the true pose, with and without the start.

Each policy plays the task's own environment (`envs.tasks.LaserTaskEnv("homing", world)`: its
excursion, its 200-step budget, its success) from the same resets, and steers with the
true pose along shortest paths on the planner's grid (`analysis.map.ceilings.grid_graph`: the
true-pose planner's distances, walls kept at a distance):

- `told`: knows the start room and drives to it (what full knowledge reaches with this driver);
- `tour`: knows the room it is in and its pose but not the start: it drives to the likeliest
  start room given the hand-over room (`envs.tasks.handovers`, counted on other resets) and,
  if the episode has not ended on entering it, on to the next likeliest; no memory of the
  excursion at all;
- `guess`: the same without touring (it stops after the first room): the hand-over bound of
  `envs.tasks.memoryless_bound`, played.

`tour` against `told` is how much of the task a memory is needed for. It also counts what the
hand-over guess wins on the 50 starts every agent is evaluated on (`rl.runner.evaluate`: 8
environments seeded `EVAL_SEED + i`, 7, 7, 6, ... episodes each; no step draws a random
number, so the starts do not depend on the policy). Usage:

    python docs/results/rl/homing_paper/memoryless_tour.py [--world rooms1] [--resets 1000] [--out tour.json]
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
from scipy.sparse.csgraph import dijkstra

from sensorimotor.analysis.map.ceilings import RESOLUTION, _cell_of, grid_graph
from sensorimotor.envs.laser_world import MAX_TURN, WALL_MARGIN
from sensorimotor.envs.tasks import HANDOVER_RESETS, HOMING_BUDGET, LaserTaskEnv, handovers
from sensorimotor.rl.runner import EVAL_SEED
from sensorimotor.sim import core as sim
from sensorimotor.sim.world import point_in_polygon
from sensorimotor.stats import wilson_interval

FIRST_RESET = 100_000  # the resets played: disjoint from the hand-over counts' (0 .. 999)
AHEAD = 4  # grid cells (2 units) down the shortest path: where each step turns toward


def room_distances(world, graph, shape) -> np.ndarray:
    """(rooms, cells) the grid's path length from each cell to the nearest cell inside each room."""
    nx_, ny = shape
    gx, gy = np.meshgrid(np.arange(nx_), np.arange(ny), indexing="xy")
    cx, cy = (gx.ravel() + 0.5) * RESOLUTION, (gy.ravel() + 0.5) * RESOLUTION
    out = []
    for room in world.rooms:
        inside = np.flatnonzero(point_in_polygon(room.polygon, cx, cy))
        d = dijkstra(graph, directed=False, indices=inside, min_only=True)
        out.append(np.where(np.isfinite(d), d, 1e6))
    return np.stack(out)


def action(env, far, graph, shape) -> np.ndarray:
    """Move a full step along the heading (stopped by the wall ahead, as ``sim.move`` stops
    it), then turn toward the cell ``AHEAD`` cells down the grid's shortest path from there:
    the env moves first, then turns, and the path goes round the walls."""
    x, y, h, _ = sim.move(env.segments, *env.pose, 1.0, 0.0, env.ahead_range, WALL_MARGIN)
    cell = _cell_of((x, y), shape)
    for _ in range(AHEAD):
        lo, hi = graph.indptr[cell], graph.indptr[cell + 1]
        if lo == hi or far[cell] == 0:
            break
        nxt = graph.indices[lo:hi]
        cell = int(nxt[np.argmin(graph.data[lo:hi] + far[nxt])])
    gx, gy = cell % shape[0], cell // shape[0]
    t = math.atan2((gy + 0.5) * RESOLUTION - y, (gx + 0.5) * RESOLUTION - x)
    r = (t - h + math.pi) % (2 * math.pi) - math.pi
    return np.array([1.0, r / MAX_TURN])  # normalised: d = 1, the turn


def play(env, order, dist, graph, shape, seed: int) -> bool:
    """One episode from reset ``seed``: visit the rooms of ``order`` (a function of the
    start and hand-over rooms) in turn; True if the env reports success."""
    env.reset(seed=seed)
    targets = list(order(env.start_room, env._room()))
    for _ in range(HOMING_BUDGET):
        while targets and env._room() == targets[0]:
            targets.pop(0)  # entered and not the start (else the episode ended)
        if not targets:
            return False
        _, _, terminated, _, info = env.step(action(env, dist[targets[0]], graph, shape))
        if terminated:
            return bool(info["is_success"])
    return False


def evaluation_guess(world: str, likeliest: dict, episodes: int = 50, n_envs: int = 8) -> int:
    """Episodes of the agents' evaluation that guessing the likeliest start room from the
    hand-over room wins (the room guessed is the start room)."""
    wins = 0
    for i in range(n_envs):
        env = LaserTaskEnv("homing", world)
        for k in range(episodes // n_envs + (i < episodes % n_envs)):
            env.reset(seed=EVAL_SEED + i if k == 0 else None)
            wins += likeliest[env._room()][0] == env.start_room
    return wins


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", default="rooms1")
    parser.add_argument("--resets", type=int, default=1000)
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    t0 = time.time()
    env = LaserTaskEnv("homing", args.world)
    graph, shape = grid_graph(env.world)
    dist = room_distances(env.world, graph, shape)
    counts = handovers(args.world, HANDOVER_RESETS)  # (start, hand-over)
    likeliest = {h: [int(k) for k in np.argsort(-counts[:, h], kind="stable") if k != h]
                 for h in range(len(env.world.rooms))}  # fmt: skip
    policies = {
        "told": lambda start, here: [start],
        "tour": lambda start, here: likeliest[here],
        "guess": lambda start, here: likeliest[here][:1],
    }
    seeds = range(FIRST_RESET, FIRST_RESET + args.resets)
    result = {"world": args.world, "resets": args.resets, "first_reset": FIRST_RESET,
              "budget": HOMING_BUDGET, "handover_counts": counts.tolist(), "success": {}}  # fmt: skip
    for name, order in policies.items():
        wins = sum(play(env, order, dist, graph, shape, s) for s in seeds)
        p = wins / args.resets
        lo, hi = wilson_interval(wins, args.resets)
        result["success"][name] = {"rate": p, "wins": wins, "wilson_95": [lo, hi]}
        print(f"{name:6s} {p:.3f}  [Wilson 95 % {lo:.3f}, {hi:.3f}]  ({wins} of {args.resets})")
    wins = evaluation_guess(args.world, likeliest)
    result["evaluation_starts"] = {"episodes": 50, "guess_wins": wins}
    print(f"the hand-over guess on the agents' 50 evaluation starts: {wins} of 50")
    result["seconds"] = round(time.time() - t0, 1)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1, allow_nan=False)


if __name__ == "__main__":
    main()
