"""The package's version: what databases, run folders and reports record of the code."""

__version__ = "0.1.0"
