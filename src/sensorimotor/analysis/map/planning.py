"""Planning with the map, in the simulator, with the real sensors and the frozen encoder.

An episode: a random start pose and a random goal position (both ``sim.core.sample_start``,
whatever the map); the goal is reached when the agent's true position comes within
``GOAL_RADIUS`` of it. The map aims at its goal states (``goal_states``: the well-visited states
whose mean position, their place field's centre on the training split, lies near the goal). At
every step the agent reads its lasers (``sim.core.read_sensors``), encodes the readings (the
raw readings / range, or the run's ``encode``, recurrent state carried; a motor memory also
reads the command just executed), takes the cell
(k-means), updates the map's filter, and acts:

- the wall-avoidance reflex of the paper's behaviour is kept, on the paper's five rays as the
  behaviour read them whatever rays the database records (``reflex_reading``): a reading
  below 1 forces the turn-around (the agent never crosses a wall, and the map only knows the
  turn in that case);
- otherwise it takes the moving action (right, straight, left) whose expected distance to the
  goal after one step is the smallest: ``sum_s alpha(s) sum_s' T[a, s, s'] D(s')``, with
  ``D`` the shortest-path distance to the goal states in the map's graph (edge cost
  ``1 - log max_a T[a, s, s']``, Dijkstra): the plan is re-made from the filter at each step.
  On the map of a lattice behaviour (``Moves.turn``), whose places are few and whose moves are
  exact, the graph's edges are the transitions the Viterbi path took and the pseudocount's
  jumps a dear fallback (``reverse_graph(own_paths=True)``): with every entry of the blocks as
  an edge, the grid's map had paths shorter than the world's, and its planner 0.18 of the
  validation pairs against 0.42 (``docs/results/map/grid``);
- an action is executed as the behaviour that recorded the database would have executed it
  (``Moves``), so the map's statistics hold: under the paper's behaviour a command drawn from
  its range for that bin (``d ~ U(0, 1)``, ``r`` uniform in the bin); under the lattice
  behaviour the lattice's own command (right: turn by -pi/6, straight: forward 0.9, left: turn
  by +pi/6; the grid's by pi/2), from a start heading on the lattice, snapped after each step
  as it records.

The baseline is the same behaviour's random walk (``sim.core.behaviour``, or the lattice's) for
the same budget from the same start; success rate = the fraction of episodes that reach their
goal. The smooth behaviour's commands are planned as the paper's (its turning rate has a state
the planner does not keep).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sensorimotor.analysis.map.cells import STRAIGHT, action_bins
from sensorimotor.analysis.map.chmm import CloneHMM
from sensorimotor.sim.behaviours import (
    BEHAVIOURS,
    LATTICE_STEP,
    TURNS,
    lattice_behaviour,
    snap_heading,
)
from sensorimotor.sim.core import (
    DEFAULT_LAYOUT,
    TURN_THRESHOLD,
    SensorLayout,
    apply_motor,
    behaviour,
    read_sensors,
    sample_start,
    wrap_angle,
)
from sensorimotor.sim.world import World

MAX_PAIRS = 3_000  # 10 x N_PAIRS: planning them takes minutes, not hours (cli.app.MAX_PAIRS)
N_PAIRS = 300  # start/goal pairs: 2 binomial SEs of a 5-seed mean lead (0.035) < its margin
BUDGET = 400  # steps an episode may take
GOAL_RADIUS = 4.0
FALLBACK = 100.0  # a jump's extra cost on a lattice map: dearer than any path of its own edges
N_TRACES = 2  # the map's first reached and first missed episodes, this many each (the figure)
MOVING = (1, 2, 3)  # right, straight, left (cells.ACTION_NAMES)
# Under a lattice behaviour, the share of the map planner's steps handed to the behaviour's own
# step: its greedy plan cycled in place where the belief was spread (docs/results/map/grid).
# Chosen on validation (the seed-1 grid maps of Rooms1 and Rooms2, 100 pairs of pair seed 1):
# 0: 0.75, 0.81 of the goals; 0.05: 0.87, 0.96; 0.15: 0.88, 0.95 (a tie; the fewer steps).
# Not validated under the paper's behaviour, whose maps plan with none.
EXPLORE = 0.05
R_RANGE = {1: (-math.pi / 6, -STRAIGHT), 2: (-STRAIGHT, STRAIGHT), 3: (STRAIGHT, math.pi / 6)}


@dataclass(frozen=True)
class Moves:
    """How the planners move in the regime of the behaviour that recorded the map's database
    (``Database.behaviour``; module docstring): the command of each moving action, the
    behaviour's own step (the reflex and the random baseline), its headings."""

    behaviour: str = "paper"

    @property
    def turn(self) -> float:
        """The step of the behaviour's heading lattice (``sim.behaviours.TURNS``; 0: none)."""
        return TURNS[BEHAVIOURS.index(self.behaviour)]

    def lattice_command(self, action: int) -> tuple[float, float]:
        """A lattice's command of moving ``action``: right, straight (forward), left."""
        return ((0.0, -self.turn), (LATTICE_STEP, 0.0), (0.0, self.turn))[MOVING.index(action)]

    def command(self, action: int, rng: np.random.Generator) -> tuple[float, float]:
        """The command that executes moving ``action``."""
        if self.turn:
            return self.lattice_command(action)
        lo, hi = R_RANGE[action]
        return float(rng.random()), float(lo + (hi - lo) * rng.random())

    def expected(self, action: int) -> tuple[float, float]:
        """The mean command of moving ``action`` (the true-pose planner's look-ahead)."""
        return self.lattice_command(action) if self.turn else (0.5, 0.5 * sum(R_RANGE[action]))

    def walk(self, min_reading: float, rng: np.random.Generator) -> tuple[float, float]:
        """The behaviour's own step: the turn-around below TURN_THRESHOLD, else a random move."""
        if self.turn:
            return lattice_behaviour(min_reading, rng.random(), self.turn)
        return behaviour(min_reading, rng.random(), rng.random())

    def heading(self, heading: float) -> float:
        """A heading as the behaviour keeps it: on its lattice, snapped to it."""
        return wrap_angle(snap_heading(heading, self.turn)) if self.turn else heading


PAPER_MOVES = Moves()


def goal_distances(model: CloneHMM, goals: np.ndarray, graph=None) -> np.ndarray:
    """(S,) cost of the best path from each state to the nearest of the ``goals`` states (inf
    where none): Dijkstra on the map's ``reverse_graph`` (pass it to reuse it across goals)."""
    from scipy.sparse.csgraph import dijkstra

    graph = reverse_graph(model) if graph is None else graph
    found = dijkstra(graph, directed=True, indices=np.asarray(goals), min_only=True)
    return found[:-1]  # the hub is not a state


def reverse_graph(model: CloneHMM, own_paths: bool = False):
    """(S + 1, S + 1) scipy sparse: edge costs ``1 - log max_a T[a, s, s']`` (a step, plus its
    surprise) between active states, with ``T`` above 1e-6, reversed (paths to the goals), and
    a hub node S; see the comment on the jumps below. The same for every goal. With
    ``own_paths`` (a lattice behaviour's map), the edges are the transitions the Viterbi path
    took, and a jump costs ``FALLBACK`` more: a fallback where those lead nowhere."""
    from scipy.sparse import csr_matrix

    T, S = model.T, model.n_states
    source, target, _, p = T.entries()
    keep = model.active[source] & model.active[target] & (source != target) & (p >= 1e-6)
    if own_paths:  # the pseudocount's entries of a block would be wormholes between places
        keep &= model.counts.ravel() > 0
    source, target, p = source[keep], target[keep], p[keep]
    first = np.lexsort((-p, target, source))  # the likeliest action first for each pair
    pair = source[first] * S + target[first]
    first = first[np.r_[True, pair[1:] != pair[:-1]]]
    source, target, cost = source[first], target[first], 1.0 - np.log(p[first])
    # Every active state also jumps to every other by the pseudocount's share of its row (the
    # rest, about 1e-3 / the row's count, above the 1e-6 threshold): a costly jump (about 10 to
    # 12) that caps every distance, so the plan steers by the map's transitions near the goal
    # states only. It runs through one hub node S: s -> S costs -log max_a rest[a, s], S -> s'
    # costs 1, so the jump costs 1 - log max_a rest, as a direct edge would (a transition's own
    # edge is never dearer: a block's entries are at least the rest of their row).
    # Without the jumps (edges = the training path's transitions only), the product map of
    # Rooms1 and Rooms2 (Rec-SM seed 0) planned worse: 0.28 and 0.28 against 0.42 and 0.34.
    jump = T.rest.max(axis=0)
    out = np.flatnonzero(model.active & (jump >= 1e-6))
    into = np.flatnonzero(model.active)
    source = np.concatenate([source, out, np.full(len(into), S)])
    target = np.concatenate([target, np.full(len(out), S), into])
    landing = np.full(len(into), 1.0 + (FALLBACK if own_paths else 0.0))
    cost = np.concatenate([cost, -np.log(jump[out]), landing])
    return csr_matrix((cost, (target, source)), shape=(S + 1, S + 1))


def goal_states(
    model: CloneHMM, state_mean: np.ndarray, occupancy: np.ndarray, goal_xy: np.ndarray
) -> np.ndarray:
    """The map's states for a goal position: the well-visited active states (occupancy at least
    the median) whose mean position lies within GOAL_RADIUS of it, or the nearest such one."""
    active = np.flatnonzero(model.active)
    candidates = active[occupancy[active] >= np.median(occupancy[active])]
    dist = np.hypot(*(state_mean[candidates] - goal_xy).T)
    near = candidates[dist <= GOAL_RADIUS]
    return near if len(near) else candidates[[int(np.argmin(dist))]]


def encoder_of(run, max_range: float):
    """A factory of online encoders: ``encoder_of(run, r)()`` is a function from one reading
    (R,) and the command (d, r) executed just before it (None at the start) to the reading's
    representation (D,), carrying a recurrent model's state from one call to the next (``run``
    is ``"raw"``: the readings / range, or a loaded ``evaluate.Run``). Only a motor memory
    (Rec-SMA) reads the command, as m_{t-1} beside s_t, zero at the start as in training."""
    if isinstance(run, str):
        return lambda: lambda readings, _command: np.asarray(readings, dtype=np.float64) / max_range
    import torch

    from sensorimotor.sim.database import scale_motors, scale_sensors

    motor_memory = run.model.config.motor_memory

    def fresh():
        state = None

        @torch.no_grad()
        def encode(readings: np.ndarray, command: tuple[float, float] | None) -> np.ndarray:
            nonlocal state
            s = torch.from_numpy(scale_sensors(readings[None], max_range))[None]  # (1, 1, R)
            motors = None
            if motor_memory:
                motors = torch.zeros(1, 1, 2)  # m_t: not chosen yet, and z_t does not read it
                if state is not None and command is not None:
                    last = torch.from_numpy(scale_motors(np.array([command])))  # (1, 2)
                    state = (state[0], state[1], last[None])  # m_{t-1}: (1, 1, 2)
            z, state = run.model.encode(s, state, motors)  # (1, 1, D)
            return z[0, 0].numpy().astype(np.float64)

        return encode

    return fresh


def run_episode(
    world: World,
    layout: SensorLayout,
    encoder,
    kmeans,
    model: CloneHMM,
    distances: np.ndarray,
    goal_xy: np.ndarray,
    start: tuple[float, float, float],
    rng: np.random.Generator,
    budget: int = BUDGET,
    use_map: bool = True,
    trace: list | None = None,
    moves: Moves = PAPER_MOVES,
    explore: float = 0.0,
) -> int | None:
    """Steps to the goal (None if not reached within ``budget``) from ``start``; with
    ``use_map`` the map's planner acts, otherwise the behaviour's random walk (``moves``). The
    positions visited are appended to ``trace`` if given. ``explore``: the share of the map's
    steps on which the behaviour's own step replaces the plan's (0: none, no draw made)."""
    C = model.n_clones
    far = np.where(np.isfinite(distances), distances, np.nan)
    far = np.where(np.isnan(far), np.nanmax(far) + 10.0 if np.isfinite(far).any() else 0.0, far)
    after = np.stack([model.T.after(a, far) for a in MOVING]) if use_map else None  # (3, S)
    x, y, heading = start[0], start[1], moves.heading(start[2])
    encode = encoder() if use_map else None
    centres = kmeans.cluster_centers_  # (K, D): the nearest is the cell (KMeans.predict)
    alpha = cell = action = command = None
    for t in range(budget + 1):
        if trace is not None:
            trace.append((x, y))
        if math.hypot(x - goal_xy[0], y - goal_xy[1]) <= GOAL_RADIUS:
            return t
        if t == budget:
            return None
        pose = np.array([x, y, heading])
        readings = read_sensors(world, pose, layout)[0] if use_map else None
        nearest = reflex_reading(world, pose, layout, readings)
        if not use_map:
            x, y, heading = apply_motor(x, y, heading, *moves.walk(nearest, rng))
            heading = moves.heading(heading)
            continue
        new_cell = int(np.argmin(((centres - encode(readings, command)) ** 2).sum(axis=1)))
        if alpha is None:
            alpha = np.full(C, 1.0 / C)
        else:
            alpha = alpha @ model.T.block(action, cell, new_cell)
            alpha = alpha / alpha.sum() if alpha.sum() > 0 else np.full(C, 1.0 / C)
        cell = new_cell
        if nearest < TURN_THRESHOLD:
            action = 0
            d, r = moves.walk(nearest, rng)
        elif explore and rng.random() < explore:
            d, r = moves.walk(nearest, rng)
            action = int(action_bins(np.array([[d, r]]))[0])  # as the map's training saw it
        else:
            expected = after[:, cell * C : (cell + 1) * C] @ alpha  # (3,)
            action = MOVING[int(np.argmin(expected + 1e-9 * rng.random(3)))]
            d, r = moves.command(action, rng)
        command = (d, r)
        x, y, heading = apply_motor(x, y, heading, d, r)
        heading = moves.heading(heading)
    return None


def reflex_reading(
    world: World, pose: np.ndarray, layout: SensorLayout, readings: np.ndarray | None = None
) -> float:
    """The smallest reading the behaviours' reflex sees: the paper's five noiseless rays, which
    the behaviour that recorded a database read whatever rays it recorded (``core._rollout``;
    with 16 rays over a full turn, a wall behind the robot would turn it for ever). ``readings``
    of ``layout`` at ``pose``, if given, are used when ``layout`` is the paper's."""
    if readings is None or layout != DEFAULT_LAYOUT:
        readings = read_sensors(world, pose, DEFAULT_LAYOUT)[0]
    return float(readings.min())


def start_goal_pairs(world: World, seed: int, n_pairs: int) -> list[tuple]:
    """The episodes' (goal position (2,), start pose, two episode seeds) for ``seed``: a goal
    and a start (free positions, ``sample_start``), then a seed for the map's episode and one
    for the random behaviour's, pair after pair; the true-pose ceiling plans the same pairs."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_pairs):
        goal_xy = np.array(sample_start(world, rng)[:2])
        start = sample_start(world, rng)
        out.append((goal_xy, start, rng.integers(0, 2**32, 2)))
    return out


def planning(
    world: World,
    layout: SensorLayout,
    encoder,
    kmeans,
    model: CloneHMM,
    state_mean: np.ndarray,
    occupancy: np.ndarray,
    seed: int = 0,
    n_pairs: int = N_PAIRS,
    budget: int = BUDGET,
    progress=None,
    moves: Moves = PAPER_MOVES,
    explore: float | None = None,
) -> tuple[dict, list]:
    """Success rates of the map's planner and of the random behaviour over ``n_pairs``
    start/goal pairs (module docstring), and the map's first N_TRACES reached and first
    N_TRACES missed episodes, in pair order, as (pair, positions (n, 2), goal (2,), steps or
    None). ``encoder()`` returns a fresh function from
    one reading (R,) and the command before it to its representation (D,);
    ``progress(pairs done, success so far)`` after each pair; ``explore``: ``run_episode``'s,
    for the map's planner (default: ``EXPLORE`` under a lattice behaviour, else 0)."""
    if explore is None:
        explore = EXPLORE if moves.turn else 0.0
    reached = {"map": [], "random": []}
    traces = []
    graph = reverse_graph(model, own_paths=bool(moves.turn))
    for pair, (goal_xy, start, seeds) in enumerate(start_goal_pairs(world, seed, n_pairs)):
        trace: list = []
        goals = goal_states(model, state_mean, occupancy, goal_xy)
        distances = goal_distances(model, goals, graph)
        for name, seed_ in zip(("map", "random"), seeds, strict=True):
            steps = run_episode(
                world,
                layout,
                encoder,
                kmeans,
                model,
                distances,
                goal_xy,
                start,
                np.random.default_rng(seed_),
                budget,
                use_map=name == "map",
                trace=trace if name == "map" else None,
                moves=moves,
                explore=explore if name == "map" else 0.0,
            )
            reached[name].append(steps)
        steps = reached["map"][-1]
        if sum((t[3] is None) == (steps is None) for t in traces) < N_TRACES:
            traces.append((pair, np.array(trace), goal_xy, steps))
        if progress is not None:
            progress(pair + 1, sum(s is not None for s in reached["map"]) / (pair + 1))
    out = {"success": {}, "median_steps": {}, "pairs": n_pairs, "budget": budget}
    for name, steps in reached.items():
        done = [s for s in steps if s is not None]
        out["success"][name] = len(done) / n_pairs
        out["median_steps"][name] = float(np.median(done)) if done else None
    out["goal_radius"] = GOAL_RADIUS
    out["explore"] = explore
    out["moves"] = moves.behaviour  # whose commands executed the actions
    return out, traces
