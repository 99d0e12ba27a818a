"""What walks the robot: the paper's wall-avoiding random behaviour and the others, each a numba
function of a step's uniforms (and its own state), which ``core._rollout`` calls by id.

    paper    d ~ U(0, 1), r ~ U(-pi/6, pi/6)                          (section IV.C)
    smooth   d ~ U(0, 1), r an Ornstein-Uhlenbeck turning rate          (issue 36)
    lattice  forward LATTICE_STEP, or turn +-pi/6, on a heading lattice (issue 37)
    grid     the lattice with turns of pi/2: 4 headings, positions on a grid of LATTICE_STEP

Every one turns around when a reading is below ``TURN_THRESHOLD`` (the paper's reflex), so
that with ``d < 1`` the point robot never reaches a wall.
"""

from __future__ import annotations

import math

import numba

from sensorimotor.errors import InputError

TURN_THRESHOLD = 1.0  # units; the behaviour turns around when a reading is below this


BEHAVIOURS = ("paper", "smooth", "lattice", "grid")
"""``generate --behaviour``: a name's index is the id ``_rollout`` takes (``PAPER``, ``SMOOTH``,
``LATTICE``, ``GRID``)."""
PAPER, SMOOTH, LATTICE, GRID = 0, 1, 2, 3
UNIFORMS = (2, 4, 1, 1)
"""Uniforms each behaviour draws a step, by id (the paper's two keep their bytes)."""
PAPER_TURN_SD = math.pi / 6.0 / math.sqrt(3.0)
"""The standard deviation of the paper's turn ``U(-pi/6, pi/6)`` (0.302 rad)."""
SMOOTH_TAU = 5.0
"""Steps: the time constant of the smooth behaviour's turning rate (an Ornstein-Uhlenbeck
process sampled once a step; docs/DESIGN.md, "The smooth behaviour")."""
SMOOTH_A = math.exp(-1.0 / SMOOTH_TAU)
"""The turning rate's lag-1 autocorrelation, ``exp(-1 / tau)`` (0.819)."""
SMOOTH_SD = PAPER_TURN_SD * math.sqrt((1.0 - SMOOTH_A) / (1.0 + SMOOTH_A))
"""The turning rate's stationary sd (0.095 rad): the heading then diffuses as fast as under
the paper's behaviour over many steps (the variance of a sum of n rates tends to
``n SD^2 (1 + a) / (1 - a) = n PAPER_TURN_SD^2``)."""
SMOOTH_KICK = SMOOTH_SD * math.sqrt(1.0 - SMOOTH_A * SMOOTH_A)
"""The sd of a step's innovation, so that the rate stays at SMOOTH_SD."""


def check_behaviour(name: str) -> int:
    """The id of behaviour ``name``; InputError naming ``--behaviour`` when it is unknown."""
    if name not in BEHAVIOURS:
        raise InputError(f"--behaviour must be one of {', '.join(BEHAVIOURS)}, got {name!r}")
    return BEHAVIOURS.index(name)


@numba.njit(cache=True)
def reflex(u):
    """The wall reflex of every behaviour from a uniform in [0, 1): ``(0, r)``,
    ``r ~ U(pi - pi/10, pi + pi/10)`` (turn around)."""
    return 0.0, math.pi - math.pi / 10.0 + u * (math.pi / 5.0)


@numba.njit(cache=True)
def behaviour(min_reading, u0, u1):
    """The paper's wall-avoiding random behaviour (section IV.C) from two uniforms in [0, 1).

    If a reading is below 1: ``(0, r)``, ``r ~ U(pi - pi/10, pi + pi/10)`` (turn around);
    else ``d ~ U(0, 1)``, ``r ~ U(-pi/6, pi/6)``. Returns ``(d, r)``.
    """
    if min_reading < TURN_THRESHOLD:
        return reflex(u1)
    return u0, -math.pi / 6.0 + u1 * (math.pi / 3.0)


@numba.njit(cache=True)
def smooth_behaviour(min_reading, u0, u1, u2, u3, rate):
    """A RatInABox-like smooth random motion from four uniforms in [0, 1) and the turning
    rate of the step before: the rate follows an Ornstein-Uhlenbeck process (mean 0, time
    constant SMOOTH_TAU steps, stationary sd SMOOTH_SD; its normal innovation by Box-Muller
    from ``u2, u3``), the forward speed is ``u0`` (``U(0, 1)``, the paper's range), and the
    paper's reflex (from ``u1``) replaces the command when a reading is below 1; the rate
    runs on underneath. Returns ``(d, r, rate)``.
    """
    z = math.sqrt(-2.0 * math.log(1.0 - u2)) * math.cos(2.0 * math.pi * u3)
    rate = SMOOTH_A * rate + SMOOTH_KICK * z
    if min_reading < TURN_THRESHOLD:
        d, r = reflex(u1)
        return d, r, rate
    return u0, rate, rate


LATTICE_TURN = math.pi / 6.0
"""The lattice behaviour's turn: headings stay on the 12 multiples of it."""
GRID_TURN = math.pi / 2.0
"""The grid behaviour's turn: 4 headings, so that forward steps keep the position on
``start + LATTICE_STEP Z^2`` (with 12 headings the positions reached are dense: DESIGN.md)."""
LATTICE_STEP = 0.9
"""Units the lattice behaviours move forward: below TURN_THRESHOLD, so they never reach a wall."""
TURNS = (0.0, 0.0, LATTICE_TURN, GRID_TURN)
"""By id: the step of each behaviour's heading lattice (0: no lattice)."""


@numba.njit(cache=True)
def lattice_behaviour(min_reading, u0, turn):
    """A behaviour whose commands move the robot near-deterministically (issue 37: a map in its
    own regime), from one uniform in [0, 1): forward ``LATTICE_STEP`` (u0 < 1/2), turn
    ``+turn`` (u0 < 3/4) or ``-turn`` (``TURNS``: pi/6 for the lattice, pi/2 for the grid); the
    reflex turns around by pi - turn, pi or pi + turn (a third each: by pi alone, a robot beside
    a wall turned from it to it for ever), so the heading stays on the lattice
    (``core._rollout`` snaps it against rounding)."""
    if min_reading < TURN_THRESHOLD:
        return 0.0, math.pi + (math.floor(3.0 * u0) - 1.0) * turn
    if u0 < 0.5:
        return LATTICE_STEP, 0.0
    if u0 < 0.75:
        return 0.0, turn
    return 0.0, -turn


@numba.njit(cache=True)
def snap_heading(heading, turn):
    """``heading`` rounded to the nearest multiple of ``turn`` (the lattice's drift)."""
    return round(heading / turn) * turn
