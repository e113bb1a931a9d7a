"""``python -m labutils.sfm TRACKS.txt K.txt --out RESULT.json``: see :func:`labutils.sfm.main`."""
import sys

from ..core import cli as _cli
from .incremental import main

sys.exit(_cli.run(main))
