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


def rollout(
    segments: Sequence[Segment],
    angles: Sequence[float],
    max_range: float,
    start: tuple[float, float, float],
    uniforms: Sequence[Sequence[float]],
    noise: Sequence[Sequence[float]] | None = None,
) -> tuple[list[list[float]], list[list[float]], list[list[float]]]:
    """Run one step per row of ``uniforms`` (T, 2) from ``start``: (sensors, motors, poses).

    Row t: the pose, the readings taken there (plus ``noise[t]``, clipped to [0, max_range];
    the behaviour sees the noiseless ones) and the command chosen from them. Ray directions come
    from the heading's ``cos``/``sin`` and the angle-sum identities, as in the numba kernel.
    """
    cos_a = [math.cos(a) for a in angles]
    sin_a = [math.sin(a) for a in angles]
    x, y, heading = start
    sensors, motors, poses = [], [], []
    for t, (u0, u1) in enumerate(uniforms):
        poses.append([x, y, heading])
        ch = math.cos(heading)
        sh = math.sin(heading)
        lowest = max_range
        row = []
        for i in range(len(angles)):
            reading = cast(
                segments,
                x,
                y,
                ch * cos_a[i] - sh * sin_a[i],
                sh * cos_a[i] + ch * sin_a[i],
                max_range,
            )
            lowest = min(lowest, reading)
            extra = 0.0 if noise is None else noise[t][i]
            row.append(min(max(reading + extra, 0.0), max_range))
        sensors.append(row)
        d, r = behaviour(lowest, u0, u1)
        motors.append([d, r])
        x, y, heading = apply_motor(x, y, heading, d, r)
    return sensors, motors, poses
