"""``python -m labutils.bench {ba,notebooks}``: the command of :mod:`labutils.tools.bench`.

A thin entry point, so that the command keeps its short name while its code lives with the tools."""
import sys

from .core import cli as _cli
from .tools.bench import main

if __name__ == "__main__":
    sys.exit(_cli.run(main))
