"""Representation learning by sensorimotor prediction (Kulak & Garcia Ortiz), reproduced."""

__version__ = "0.1.0"

from sensorimotor.errors import InputError

MAX_SEED = 2**32 - 1  # the largest seed that every seeded library here accepts

__all__ = ["MAX_SEED", "InputError", "__version__"]
