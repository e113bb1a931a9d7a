"""The workbook's house rules for what is committed: notebook names, no stored outputs, checkpoints present.

The rules hold for the notebooks git tracks, as git would commit them (the index), not for the working tree: a
student who opens the notebooks in JupyterLab (which makes ``notebooks/.ipynb_checkpoints/``) or runs one and saves
it with its outputs must not break the suite. Outside a git checkout (a tarball) the working tree is checked
instead, and the test says so with a warning.
"""
import importlib.util
import json
import re
import subprocess
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _git(*args):
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, check=True).stdout


def _blob(path):
    """The notebook as git would commit it: the index; the last commit during a merge conflict."""
    try:
        return _git("cat-file", "blob", f":{path}")
    except subprocess.CalledProcessError:
        return _git("cat-file", "blob", f"HEAD:{path}")


def committed_notebooks():
    """``(where, {path: text})`` for every notebook under ``notebooks/``.

    In a git checkout: what ``git ls-files`` tracks, with the index's content. Otherwise: the working tree, leaving
    out what the ``.gitignore`` keeps out of a checkout (JupyterLab's checkpoints, ``Untitled*.ipynb``).
    """
    try:
        top = Path(_git("rev-parse", "--show-toplevel").decode().strip()).resolve()
    except (OSError, subprocess.CalledProcessError):
        top = None
    if top != ROOT:
        files = [p for p in sorted((ROOT / "notebooks").rglob("*.ipynb"))
                 if ".ipynb_checkpoints" not in p.parts and not p.name.startswith("Untitled")]
        return "working tree", {p.relative_to(ROOT).as_posix(): p.read_text(encoding="utf-8") for p in files}
    tracked = _git("ls-files", "-z", "--", "notebooks").decode().split("\0")
    paths = list(dict.fromkeys(p for p in tracked if p.endswith(".ipynb")))
    return "git index", {p: _blob(p).decode("utf-8") for p in paths}


WHERE, NOTEBOOKS = committed_notebooks()
CODE_NOTEBOOKS = sorted(p for p in NOTEBOOKS if re.fullmatch(r"notebooks/[^/]+\.ipynb", p))


def test_notebook_names():
    if WHERE != "git index":
        warnings.warn(f"{ROOT} is not a git checkout: checking the notebooks in the working tree (a notebook saved "
                      "with outputs fails here; in a clone the committed version is checked)", stacklevel=1)
    assert NOTEBOOKS, f"no notebooks found in {WHERE}"
    for path in NOTEBOOKS:
        assert ".ipynb_checkpoints" not in path.split("/"), f"checkpoint folder committed: {path}"
        assert re.fullmatch(r"notebooks/\d\d_[a-z0-9_]+\.ipynb", path), \
            f"{path} ({WHERE}): notebooks are named notebooks/NN_snake_case.ipynb"


@pytest.mark.parametrize("path", CODE_NOTEBOOKS, ids=lambda p: p.split("/")[-1])
def test_notebook_is_stripped_and_checked(path):
    nb = json.loads(NOTEBOOKS[path])
    name = f"{path} ({WHERE})"
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert all(not c.get("outputs") and c.get("execution_count") is None for c in code), \
        f"{name} has stored outputs: strip them before committing (python -m labutils.tools.notebook_filter makes " \
        "git do it)"
    assert any(re.search(r"^\s*assert\b", "".join(c["source"]), re.M) for c in code), \
        f"{name} has no assert checkpoint"
    md = "".join("".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "markdown").lower()
    assert "in this notebook you will" in md and "what we did" in md, f"{name}: goals and 'what we did' are missing"
    assert "default_rng(" in "".join("".join(c["source"]) for c in code), f"{name}: make one seeded rng"
    assert "np.random.seed" not in "".join("".join(c["source"]) for c in code), f"{name}: no global RNG"


def _filter_settings():
    spec = importlib.util.spec_from_file_location("notebook_filter", ROOT / "labutils" / "tools" / "notebook_filter.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("path", CODE_NOTEBOOKS, ids=lambda p: p.split("/")[-1])
def test_notebook_is_what_the_git_filter_stores(path):
    """Byte for byte what nbstripout (as python -m labutils.tools.notebook_filter sets it up) would store: then a
    notebook run and saved in JupyterLab shows no change in ``git diff``, and ``git add`` changes nothing committed."""
    nbstripout = pytest.importorskip("nbstripout", reason="nbstripout is not installed (pip install -r "
                                                          "environment.txt)")
    nbformat = pytest.importorskip("nbformat")
    settings = _filter_settings()
    text = NOTEBOOKS[path]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        nb = nbformat.reads(text, as_version=nbformat.NO_CONVERT)
        nbstripout.strip_output(nb, keep_output=None, keep_count=False, keep_id="--keep-id" in settings.CLEAN_FLAGS,
                                extra_keys=settings.NBSTRIPOUT_DEFAULT_KEYS + settings.EXTRA_KEYS)
        stored = nbformat.writes(nb)
    stored += "" if stored.endswith("\n") else "\n"
    assert stored == text, \
        f"{path} ({WHERE}) is not what the notebook filter stores (outputs, counts, kernel metadata or formatting): " \
        f"run `python -m nbstripout --keep-id --extra-keys \"{' '.join(settings.EXTRA_KEYS)}\" {path}` and commit it"


@pytest.mark.parametrize("path", CODE_NOTEBOOKS, ids=lambda p: p.split("/")[-1])
def test_notebook_names_its_kernel(path):
    """Issue 19: without ``metadata.kernelspec`` JupyterLab opens each notebook with a "Select Kernel" dialog; the
    filter keeps it, and every notebook names the plain ``python3`` kernel (the environment it is opened from)."""
    spec = json.loads(NOTEBOOKS[path]).get("metadata", {}).get("kernelspec", {})
    assert spec.get("name") == "python3" and spec.get("language") == "python", f"{path}: kernelspec {spec!r}"


def test_gitattributes_route_notebooks_through_the_filter():
    text = _blob(".gitattributes").decode() if WHERE == "git index" else (ROOT / ".gitattributes").read_text()
    lines = [line.strip() for line in text.splitlines()]
    assert "*.ipynb filter=nbstripout" in lines and "*.ipynb diff=ipynb" in lines
