"""A plain-Python reference simulator: the test oracle for ``sensorimotor.sim.core``.

No numpy vectorisation and no numba: loops over rays and segments and the ``math`` module,
written to do the SAME floating-point operations in the same order as the numba kernels, so
that the two agree to the last bit on ordinary inputs (the tests allow 1e-9). It is slow
(about 10^5 steps/s) and lives in ``tests/`` on purpose: the package has one ray caster.

Segments are sequences of ``(x0, y0, x1, y1)``; angles are relative to the heading (rad,
counter-clockwise); a reading is the distance to the first wall along the ray, or
``max_range`` when no wall is nearer.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

EPS = 1e-12  # |cross(u, e)| below this: the ray is parallel to the segment and never hits it
TURN_THRESHOLD = 1.0  # the behaviour turns around when a reading is below this (units)

Segment = tuple[float, float, float, float]


def cast(
    segments: Sequence[Segment], x: float, y: float, dx: float, dy: float, max_range: float
) -> float:
    """Distance from ``(x, y)`` along the unit direction ``(dx, dy)`` to the first segment.

    The ray ``p + t u`` meets the segment ``a + s e`` (``e = b - a``) at
    ``t = cross(a - p, e) / cross(u, e)`` and ``s = cross(a - p, u) / cross(u, e)``; a hit needs
    ``t >= 0`` and ``0 <= s <= 1`` (end points count); parallel rays (``|cross(u, e)| < EPS``)
    never hit. As in the kernel, the denominator's sign moves onto the numerators and the tests
    are made on them; only a hit is divided.
    """
    best = max_range
    for ax, ay, bx, by in segments:
        ex = bx - ax
        ey = by - ay
        qx = ax - x
        qy = ay - y
        t_num = qx * ey - qy * ex
        den = dx * ey - dy * ex
        s_num = qx * dy - qy * dx
        if den < 0.0:
            den, t_num, s_num = -den, -t_num, -s_num
        if den >= EPS and t_num >= 0.0 and 0.0 <= s_num <= den:
            t = t_num / den
            if t < best:
                best = t
    return best


def cast_rays(
    segments: Sequence[Segment],
    x: float,
    y: float,
    heading: float,
    angles: Sequence[float],
    max_range: float,
) -> list[float]:
    """Readings of the rays ``heading + angle`` (one ``cos``/``sin`` of the sum per ray)."""
    out = []
    for angle in angles:
        a = heading + angle
        out.append(cast(segments, x, y, math.cos(a), math.sin(a), max_range))
    return out


def wrap_angle(a: float) -> float:
    """The same angle in (-pi, pi]."""
    while a > math.pi:
        a -= 2.0 * math.pi
    while a <= -math.pi:
        a += 2.0 * math.pi
    return a


def behaviour(min_reading: float, u0: float, u1: float) -> tuple[float, float]:
    """The paper's rule (section IV.C) from two uniforms in [0, 1): returns ``(d, r)``.

    A reading below 1: ``(0, U(pi - pi/10, pi + pi/10))``; else ``(U(0, 1), U(-pi/6, pi/6))``.
    """
    if min_reading < TURN_THRESHOLD:
        return 0.0, math.pi - math.pi / 10.0 + u1 * (math.pi / 5.0)
    return u0, -math.pi / 6.0 + u1 * (math.pi / 3.0)


def apply_motor(
    x: float, y: float, heading: float, d: float, r: float
) -> tuple[float, float, float]:
    """Translate by ``d`` along the heading, then rotate by ``r``; heading in (-pi, pi]."""
    return x + d * math.cos(heading), y + d * math.sin(heading), wrap_angle(heading + r)


PAPER_ANGLES = (-0.6, -0.3, 0.0, 0.3, 0.6)  # the rays the behaviour reads (rad)
PAPER_RANGE = 10.0


def rollout(
    segments: Sequence[Segment],
    angles: Sequence[float],
    max_range: float,
    start: tuple[float, float, float],
    uniforms: Sequence[Sequence[float]],
    noise: Sequence[Sequence[float]] | None = None,
    relative: bool = False,
    dropped: Sequence[Sequence[bool]] | None = None,
    motor_noise: Sequence[Sequence[float]] | None = None,
) -> tuple[list[list[float]], list[list[float]], list[list[float]]]:
    """Run one step per row of ``uniforms`` (T, 2) from ``start``: (sensors, motors, poses).

    Row t: the pose, the readings taken there and the command chosen. The behaviour reads the
    paper's five rays, noiseless: the recorded ones when ``angles`` are the paper's (and the
    range at least 1), else five more cast for it alone. Recorded: the reading plus
    ``noise[t][i]`` (times the reading when ``relative``), the range where ``dropped[t][i]``,
    clipped to [0, max_range]. The executed command is the chosen one plus ``motor_noise[t]``,
    its translation clipped to [0, 0.99 x the distance straight ahead]. Ray directions come
    from the heading's ``cos``/``sin`` and the angle-sum identities, as in the numba kernel.
    """
    paper = tuple(angles) == PAPER_ANGLES and max_range >= TURN_THRESHOLD
    cos_a = [math.cos(a) for a in angles]
    sin_a = [math.sin(a) for a in angles]
    cos_p = [math.cos(a) for a in PAPER_ANGLES]
    sin_p = [math.sin(a) for a in PAPER_ANGLES]
    x, y, heading = start
    sensors, motors, poses = [], [], []
    for t, (u0, u1) in enumerate(uniforms):
        poses.append([x, y, heading])
        ch = math.cos(heading)
        sh = math.sin(heading)
        recorded = [
            cast(segments, x, y, ch * c - sh * s, sh * c + ch * s, max_range)
            for c, s in zip(cos_a, sin_a, strict=True)
        ]
        seen = recorded
        if not paper:
            seen = [
                cast(segments, x, y, ch * c - sh * s, sh * c + ch * s, PAPER_RANGE)
                for c, s in zip(cos_p, sin_p, strict=True)
            ]
        lowest = min([max_range if paper else PAPER_RANGE, *seen])
        row = []
        for i, reading in enumerate(recorded):
            value = reading
            if noise is not None:
                value = value + (value * noise[t][i] if relative else noise[t][i])
            if dropped is not None and dropped[t][i]:
                value = max_range
            row.append(min(max(value, 0.0), max_range))
        sensors.append(row)
        d, r = behaviour(lowest, u0, u1)
        motors.append([d, r])
        if motor_noise is not None:
            d = min(max(d + motor_noise[t][0], 0.0), 0.99 * seen[2])
            r = r + motor_noise[t][1]
        x, y, heading = apply_motor(x, y, heading, d, r)
    return sensors, motors, poses
