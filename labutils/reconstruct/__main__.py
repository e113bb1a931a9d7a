"""``python -m labutils.reconstruct PHOTOS_DIR --out RESULT.json``: see :mod:`labutils.reconstruct.cli`."""
import sys

from ..core import cli as _cli
from .cli import main

sys.exit(_cli.run(main))
