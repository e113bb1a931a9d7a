"""What the tests of the notebooks' checkpoints (``tests/test_checkpoints_*.py``) share.

A checkpoint test runs the notebook's own cells, found by their tags (``setup``, ``checkpoint-<name>``), not a copy
of them, once with the library and once with a plausible wrong function bound in its place. A plain module,
imported as ``from _checkpoints import ...`` (pytest puts ``tests/`` on ``sys.path``; see ``_exercises.py``).
"""
import functools
import json
from pathlib import Path

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"


@functools.cache
def _code_cells(notebook):
    cells = json.loads(Path(notebook).read_text(encoding="utf-8"))["cells"]
    return tuple((tuple(c.get("metadata", {}).get("tags", [])), "".join(c["source"]))
                 for c in cells if c["cell_type"] == "code")


def tagged_cells(notebook, tag):
    """The sources of ``notebook``'s code cells tagged ``tag``, in notebook order; at least one, or the test fails."""
    found = [src for tags, src in _code_cells(Path(notebook)) if tag in tags]
    assert found, f"{Path(notebook).name} has no cell tagged {tag!r}"
    return found


def run_cells(notebook, tag, ns):
    """Run the cells tagged ``tag`` in the namespace ``ns`` (a traceback names the notebook, tag and cell); ``ns``."""
    for k, src in enumerate(tagged_cells(notebook, tag)):
        exec(compile(src, f"{Path(notebook).name}[{tag} #{k}]", "exec"), ns)
    return ns
