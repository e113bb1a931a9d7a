"""``python -m labutils.bundle PROBLEM.txt --out SOLVED.txt``: see :func:`labutils.bundle.adjust.main`."""
import sys

from ..core import cli as _cli
from .adjust import main

sys.exit(_cli.run(main))
