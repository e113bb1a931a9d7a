"""The package's architecture as rules: the import layering (drawn in the README), module size, the public API,
and the lint — each a test that fails when the code drifts."""
import ast
import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

import labutils

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "labutils"

# The layers, bottom first. A module may import only modules of lower layers, or earlier ones in its own layer.
# The README draws the same layers (test_readme_draws_the_layers); add a new module where its idea belongs.
LAYERS = {
    "foundation": ["_validation", "_cli", "_blas", "datapath", "datasets", "fetch", "ransac", "robust"],
    "geometry": ["geometry"],
    "records and files": ["metrics", "scene", "formats", "bal", "middlebury", "ply"],
    "data": ["synthetic", "synthetic_images", "data"],
    "two views": ["triangulation", "epipolar", "gold_standard", "essential"],
    "correspondences": ["features", "match"],
    "camera pose": ["pnp", "rotation_averaging", "global_translations"],
    "bundle adjustment": ["reprojection", "gauge", "lm_schur", "bundle"],
    "reconstruction": ["twoview", "reconstruction", "view_selection", "global_sfm", "pointcloud", "sfm"],
    "precision": ["uncertainty", "noise_study"],
    "the 3D model": ["carving", "carve", "textured_scene", "meshing", "texturing"],
    "calibration": ["lens", "zhang", "levenberg_marquardt", "calibration", "chessboard", "rectification", "calibrate"],
    "dense stereo": ["stereo"],
    "presentation and tools": ["plotting", "plotting_calibration", "plotting_matches", "plotting_views",
                               "carving_plots", "stereo_plots", "bench", "exercises", "notebook_filter"],
}
ORDER = [m for layer in LAYERS.values() for m in layer]

# Modules longer than this hold more than one idea unless listed here with the reason.
MAX_LINES = 600
LONG_ON_PURPOSE = {
    # The 8-point refuses noisy degenerate data by GRIC, which fits F by Sampson LM from the 8-point's own
    # normalised steps: the estimator and its degeneracy test are one idea (moving the test out would make
    # a cycle), and 60 lines are the docstring's measured table of why the test is built as it is.
    "epipolar": 720,
}


def _modules():
    """{module name: [source files]}: the .py files of labutils, a subpackage counted as one module."""
    mods = {}
    for f in sorted(PKG.rglob("*.py")):
        rel = f.relative_to(PKG)
        if rel.name == "__init__.py" and len(rel.parts) == 1:
            continue
        mods.setdefault(rel.parts[0].removesuffix(".py"), []).append(f)
    return mods


def _imports(path):
    """(line, imported labutils module, at top level?) for every import of a labutils module in ``path``."""
    tree = ast.parse(path.read_text())
    top = {id(n) for n in tree.body}
    depth = len(path.relative_to(PKG).parts) - 1                # 0 for labutils/x.py, 1 for labutils/pkg/x.py
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level == 0 and (node.module or "").split(".")[0] == "labutils":
                parts = node.module.split(".")[1:]
                names = [parts[0]] if parts else [a.name for a in node.names]
            elif node.level > 0:
                up = node.level - 1 - depth                    # levels above the package root: must be 0
                parts = (node.module or "").split(".") if node.module else []
                if up < 0:                                      # inside a subpackage, relative to it
                    names = [path.relative_to(PKG).parts[0]]
                else:
                    names = [parts[0]] if parts and parts[0] else [a.name for a in node.names]
            else:
                continue
            out += [(node.lineno, n, id(node) in top) for n in names]
        elif isinstance(node, ast.Import):
            out += [(node.lineno, a.name.split(".")[1] if "." in a.name else "labutils", id(node) in top)
                    for a in node.names if a.name.split(".")[0] == "labutils"]
    return out


def test_every_module_has_a_layer():
    mods = set(_modules())
    assert mods == set(ORDER), f"not in LAYERS: {sorted(mods - set(ORDER))}; gone: {sorted(set(ORDER) - mods)}"


def test_imports_flow_one_way():
    rank = {m: k for k, m in enumerate(ORDER)}
    problems = []
    for mod, files in _modules().items():
        for f in files:
            for line, target, at_top in _imports(f):
                where = f"{f.relative_to(ROOT)}:{line}"
                if target == "labutils":
                    problems.append(f"{where} imports the package labutils itself (import the module you need)")
                elif target == mod:
                    continue                                     # within a subpackage
                elif target not in rank:
                    problems.append(f"{where} imports labutils.{target}, which is not in LAYERS")
                elif rank[target] >= rank[mod]:
                    problems.append(f"{where}: {mod} imports {target}, which is above it (or a cycle)")
                elif not at_top:
                    problems.append(f"{where}: import of {target} inside a function (import at the top)")
    assert not problems, "\n".join(problems)


def test_modules_are_one_idea_in_size():
    long = {}
    for mod, files in _modules().items():
        n = max(len(f.read_text().splitlines()) for f in files)
        if n > LONG_ON_PURPOSE.get(mod, MAX_LINES):
            long[mod] = n
    assert not long, f"modules over {MAX_LINES} lines (split them, or say why in LONG_ON_PURPOSE): {long}"


def test_readme_draws_the_layers():
    readme = (ROOT / "README.md").read_text()
    # the layers are the bottom-to-top chart; the system chart (top-down) is another block
    block = re.search(r"```mermaid\n(flowchart BT\n.*?)```", readme, re.S)
    assert block, "the README has no mermaid block (flowchart BT) drawing the layers"
    text = block.group(1)
    for layer, mods in LAYERS.items():
        sub = re.search(rf'subgraph \w+\["{re.escape(layer)}"\]\n(.*?)\n\s*end', text, re.S)
        assert sub, f"the README's diagram has no subgraph for the layer '{layer}'"
        drawn = re.findall(r"[\w.]+", sub.group(1))
        assert sorted(drawn) == sorted(mods), f"layer '{layer}': README draws {drawn}, LAYERS says {mods}"


def test_public_names_resolve():
    for name in labutils.__all__:
        assert getattr(labutils, name) is not None
    with pytest.raises(AttributeError, match="no attribute"):
        labutils.no_such_name  # noqa: B018


# Where ``rng`` may be left out, and why: the function draws nothing unless asked to.
RNG_OPTIONAL = {
    "labutils._validation.as_rng": "the check of an rng argument itself",
    "labutils.chessboard.render_board": "a noise-free drawing by default; noise > 0 without rng is a ValueError",
    "labutils.plotting.show_reconstruction": "random only for a display subset; without rng the first max_points",
}


def _every_module():
    import pkgutil
    return [importlib.import_module(m.name) for m in pkgutil.walk_packages(labutils.__path__, "labutils.")
            if not m.name.endswith("__main__")]


def test_every_module_imports_and_rng_is_keyword_only_and_required():
    """Every module imports; every public function (and public method) with an ``rng`` takes it keyword-only and
    without a default, so no call can fall back to a hidden global state or bind a seed by position."""
    import inspect
    wrong = []
    for mod in _every_module():
        for name, obj in vars(mod).items():
            if name.startswith("_") or getattr(obj, "__module__", None) != mod.__name__:
                continue
            funcs = [(name, obj)] if inspect.isfunction(obj) else \
                [(f"{name}.{k}", v) for k, v in vars(obj).items() if inspect.isfunction(v) and not k.startswith("_")] \
                if inspect.isclass(obj) else []
            for qual, f in funcs:
                p = inspect.signature(f).parameters.get("rng")
                where = f"{mod.__name__}.{qual}"
                if p is not None and where not in RNG_OPTIONAL and (p.kind is not p.KEYWORD_ONLY or
                                                                     p.default is not p.empty):
                    wrong.append(f"{where}: rng is {p.kind.name.lower()}"
                                 + ("" if p.default is p.empty else f" with default {p.default!r}"))
    assert not wrong, "rng must be keyword-only and required (def f(..., *, rng)):\n" + "\n".join(wrong)


def test_command_lines_do_not_warn():
    """``python -m labutils.X --help`` exits 0 and prints no RuntimeWarning ('found in sys.modules')."""
    for cmd in ("sfm", "bundle", "bench", "data", "notebook_filter", "calibrate", "carve", "match"):
        r = subprocess.run([sys.executable, "-W", "error::RuntimeWarning", "-m", f"labutils.{cmd}", "--help"],
                           capture_output=True, text=True, cwd=ROOT)
        assert r.returncode == 0 and "usage" in r.stdout and "Warning" not in r.stderr, (cmd, r.stderr)


def test_lint():
    ruff = importlib.util.find_spec("ruff")
    if ruff is None:
        pytest.skip("ruff is not installed (pip install -r environment.txt)")
    r = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "."], capture_output=True, text=True,
                       cwd=ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
