"""The simulated robot and its worlds: geometry and world files (``world``), ray casting,
kinematics, the wall-avoiding behaviour and rollouts (``core``), databases (``database``),
ground-truth events from pose and walls (``events``), and the drawings of a world and of what
the robot perceives (``plots``). Nothing here imports torch."""

MAX_SEED = 2**32 - 1  # the largest seed that every seeded library here accepts (and light to
# import: the command line reads it before it knows whether numba is needed)
MAX_RAYS = 1024  # rays a layout may have (here for the same reason)
MAX_LASER_RANGE = 1_000.0  # units a laser reads: 20 x the largest built-in world
