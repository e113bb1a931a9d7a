"""``python -m labutils.carve PAR_FILE --out MODEL.ply``: the command of :mod:`labutils.model.carving.cli`.

A thin entry point, so that the command keeps its short name while its code lives in the model stage."""
import sys

from .core import cli as _cli
from .model.carving.cli import main

if __name__ == "__main__":
    sys.exit(_cli.run(main))
