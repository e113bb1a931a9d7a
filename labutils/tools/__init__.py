"""Tools for maintainers and instructors: the benchmarks (``python -m labutils.bench``) and the git filter that
stores notebooks without outputs (``python -m labutils.tools.notebook_filter``).
"""
from .bench import time_notebooks, time_per_iteration, time_solvers

__all__ = ["time_notebooks", "time_per_iteration", "time_solvers"]
