"""``python -m labutils.data {list,fetch} [SET ...]``: see :mod:`labutils.data.fetch`."""
import sys

from .fetch import main

sys.exit(main())
