"""``python -m labutils.match IMAGE_DIR K.txt --out TRACKS.txt``: see :mod:`labutils.match.cli`."""
import sys

from ..core import cli as _cli
from .cli import main

sys.exit(_cli.run(main))
