"""The ``teleop`` command line."""

from .main import main

__all__ = ["main"]
