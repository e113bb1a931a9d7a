"""``python -m labutils.data {list,fetch} [SET ...]``: see :mod:`labutils.data.fetch`."""
import sys

from ..core import cli as _cli
from .fetch import main

sys.exit(_cli.run(main))
