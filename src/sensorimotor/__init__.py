"""Representation learning by sensorimotor prediction (Kulak & Garcia Ortiz), reproduced."""

__version__ = "0.1.0"

from sensorimotor.errors import InputError

__all__ = ["InputError", "__version__"]
