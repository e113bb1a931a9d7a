"""``python -m labutils.calibrate "photos/*.jpg" --board 9x6 --square 25 --out camera.json``: see
:mod:`labutils.calibrate.cli`."""
import sys

from ..core import cli as _cli
from .cli import main

sys.exit(_cli.run(main))
