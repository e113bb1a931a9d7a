"""The workbook's house rules, checked: notebook names, no stored outputs, checkpoints present."""
import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def test_notebook_names():
    for nb in (ROOT / "notebooks").rglob("*.ipynb"):
        assert ".ipynb_checkpoints" not in nb.parts, f"checkpoint folder committed: {nb}"
        assert re.fullmatch(r"\d\d_[a-z0-9_]+\.ipynb", nb.name), f"{nb.name}: notebooks are named NN_snake_case.ipynb"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_is_stripped_and_checked(path):
    nb = json.loads(path.read_text())
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert all(not c.get("outputs") and c.get("execution_count") is None for c in code), \
        f"{path.name} has stored outputs: strip them before committing"
    assert any(re.search(r"^\s*assert\b", "".join(c["source"]), re.M) for c in code), \
        f"{path.name} has no assert checkpoint"
    md = "".join("".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "markdown").lower()
    assert "in this notebook you will" in md and "what we did" in md, \
        f"{path.name}: goals and 'what we did' are missing"
    assert "default_rng(" in "".join("".join(c["source"]) for c in code), f"{path.name}: make one seeded rng"
    assert "np.random.seed" not in "".join("".join(c["source"]) for c in code), f"{path.name}: no global RNG"
