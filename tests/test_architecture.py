"""The package's architecture as rules: its rooms (one package per stage of the pipeline), the drawing of how they
depend on each other (in the README, read here), module size, what notebooks import, the public API, one LM loop,
and the lint — each a test that fails when the code drifts."""
import ast
import importlib
import inspect
import json
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import pytest

import labutils

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "labutils"

# At most this many modules and packages directly under labutils/ (the issue that made the stages: sixteen).
MAX_ROOMS = 16
# A command whose code lives in a stage but keeps its short name (python -m labutils.carve): a thin module that
# only imports the command's main from its stage and runs it.
ENTRY_POINTS = {"carve": "model", "bench": "tools"}
# Every command answers --help without a warning; the thin entry points and the stages' __main__ among them.
COMMANDS = ["sfm", "bundle", "match", "carve", "calibrate", "data", "bench", "exercises", "reconstruct",
            "tools.notebook_filter"]

# Files longer than this hold more than one idea unless listed here with the reason.
MAX_LINES = 600
LONG_ON_PURPOSE = {
    # The 8-point refuses noisy degenerate data by GRIC, which fits F by Sampson LM from the 8-point's own
    # normalised steps: the estimator and its degeneracy test are one idea (moving the test out would make
    # a cycle), and 60 lines are the docstring's measured table of why the test is built as it is. Its helpers
    # that notebook 01 calls (design_matrix, transform_points, canonical_sign, sampson_distance) check their input
    # over the unchecked kernels the estimators and RANSAC call (issue 21: checks at the door, not in the loop).
    "twoview/epipolar.py": 640,
}


def _rooms():
    """The names directly under labutils/: modules (without .py) and packages."""
    return sorted(p.stem for p in PKG.iterdir()
                  if (p.suffix == ".py" and p.name != "__init__.py") or (p.is_dir() and (p / "__init__.py").exists()))


def _stages():
    return sorted(p.name for p in PKG.iterdir() if p.is_dir() and (p / "__init__.py").exists())


def drawn_graph():
    """The README's drawing of the stages: ``(nodes, {(a, b)})`` for every ``a --> b`` (a imports b)."""
    readme = (ROOT / "README.md").read_text()
    block = re.search(r"<!-- the stages, as tests/test_architecture.py reads them -->\n```mermaid\n(.*?)```",
                      readme, re.S)
    assert block, "the README has no drawing of the stages (the mermaid block after the marker comment)"
    edges, nodes = set(), set()
    for line in block.group(1).splitlines():
        names = re.findall(r"(\w+)(?:\[[^\]]*\])?", re.sub(r"-->", " ", line.split("%%")[0]))
        if "-->" in line:
            chain = [n for n in names]
            for a, b in zip(chain, chain[1:]):
                edges.add((a, b))
        nodes.update(n for n in names if n not in {"flowchart", "BT", "TD", "TB", "LR"})
    return nodes, edges


def _resolve(path, node):
    """The imported labutils module of an ``ImportFrom`` as parts (``['core', 'geometry']``), or None."""
    parts = list(path.relative_to(PKG).with_suffix("").parts)
    package = parts[:-1]
    if node.level == 0:
        mod = (node.module or "").split(".")
        return mod[1:] if mod[0] == "labutils" else None
    base = package[:len(package) - (node.level - 1)] if node.level > 1 else package
    return base + (node.module.split(".") if node.module else [])


def _imports(path):
    """``(line, target parts, imported names, at top level?)`` for every labutils import in ``path``."""
    tree = ast.parse(path.read_text())
    top = {id(n) for n in tree.body} | {id(n) for s in tree.body if isinstance(s, ast.If) for n in s.body}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            target = _resolve(path, node)
            if target is not None:
                out.append((node.lineno, target, [a.name for a in node.names], id(node) in top))
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "labutils":
                    out.append((node.lineno, a.name.split(".")[1:], [], id(node) in top))
    return out


def _stage_of(path):
    return path.relative_to(PKG).parts[0].removesuffix(".py")


def real_graph():
    """``{(a, b): 'file:line'}``: stage (or entry point) a imports something of stage b."""
    edges = {}
    for f in sorted(PKG.rglob("*.py")):
        if f == PKG / "__init__.py":
            continue
        a = _stage_of(f)
        for line, target, _names, _ in _imports(f):
            b = target[0] if target else None
            if b is None:
                continue                               # "from labutils import x": test_imports_are_explicit
            if b != a:
                edges.setdefault((a, b), f"{f.relative_to(ROOT)}:{line}")
    return edges


def _closure(edges):
    reach = {}
    for a, b in edges:
        reach.setdefault(a, set()).add(b)
    changed = True
    while changed:
        changed = False
        for a in list(reach):
            new = set().union(*(reach.get(b, set()) for b in reach[a])) - reach[a]
            if new:
                reach[a] |= new
                changed = True
    return {(a, b) for a, bs in reach.items() for b in bs}


def test_the_rooms():
    rooms = _rooms()
    assert len(rooms) <= MAX_ROOMS, f"{len(rooms)} rooms under labutils/ (at most {MAX_ROOMS}): {rooms}"
    for name in rooms:
        if (PKG / name).is_dir():
            continue
        assert name in ENTRY_POINTS, (f"labutils/{name}.py is a module outside every stage: move it into the stage "
                                      "of its idea (or, for a command's short name, list it in ENTRY_POINTS)")
        tree = ast.parse((PKG / f"{name}.py").read_text())
        body = [n for n in tree.body if not (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))]
        thin = all(isinstance(n, (ast.Import, ast.ImportFrom, ast.If)) for n in body)
        assert thin, f"labutils/{name}.py must be a thin entry point: imports and the __main__ block only"


def test_the_drawing_is_the_import_graph():
    """The README's drawing holds every stage and every thin entry point; each arrow is a real import; every
    import between stages follows the arrows; no arrow is implied by others (so the drawing is the code's graph,
    with nothing left out and nothing to spare); and there is no cycle."""
    nodes, drawn = drawn_graph()
    assert nodes == set(_rooms()), f"drawn but not in labutils/: {sorted(nodes - set(_rooms()))}; " \
                                   f"in labutils/ but not drawn: {sorted(set(_rooms()) - nodes)}"
    real = real_graph()
    closure = _closure(drawn)
    cycle = sorted({a for a, b in closure if a == b})
    assert not cycle, f"the drawing has a cycle through {cycle}"
    problems = [f"{where}: {a} imports {b}, which no path of arrows allows (draw the arrow, or move the code)"
                for (a, b), where in sorted(real.items()) if (a, b) not in closure]
    problems += [f"the arrow {a} --> {b} is drawn, but {a} imports nothing of {b}" for a, b in sorted(drawn)
                 if (a, b) not in real]
    problems += [f"the arrow {a} --> {b} is implied by the others: remove it" for a, b in sorted(drawn)
                 if (a, b) in _closure(drawn - {(a, b)})]
    assert not problems, "\n".join(problems)


def test_imports_are_explicit_and_at_the_top():
    problems = []
    for f in sorted(PKG.rglob("*.py")):
        for line, target, _names, at_top in _imports(f):
            where = f"{f.relative_to(ROOT)}:{line}"
            if not target and f != PKG / "__init__.py":
                problems.append(f"{where} imports from the package labutils itself (import from the stage you need)")
            elif not at_top:
                problems.append(f"{where}: an import of labutils.{'.'.join(target)} inside a function (import at the "
                                "top, so the drawing sees it)")
    assert not problems, "\n".join(problems)


def test_no_private_name_crosses_a_stage():
    """What one stage takes from another is public: no ``_name``, and no module whose name starts with ``_``."""
    problems = []
    for f in sorted(PKG.rglob("*.py")):
        for line, target, names, _ in _imports(f):
            if not target or target[0] == _stage_of(f):
                continue
            private = [p for p in target if p.startswith("_")] + [n for n in names if n.startswith("_")]
            if private:
                problems.append(f"{f.relative_to(ROOT)}:{line} takes {private} from labutils.{'.'.join(target)}")
    assert not problems, "\n".join(problems)


def test_files_are_one_idea_in_size():
    long = {}
    for f in sorted(PKG.rglob("*.py")):
        rel = f.relative_to(PKG).as_posix()
        n = len(f.read_text().splitlines())
        if n > LONG_ON_PURPOSE.get(rel, MAX_LINES):
            long[rel] = n
    assert not long, f"files over {MAX_LINES} lines (split them, or say why in LONG_ON_PURPOSE): {long}"


def test_one_levenberg_marquardt_loop():
    """One LM loop with one damping rule (Nielsen's) serves every solver: no other file changes a damping."""
    rules = [re.compile(r"1\s*/\s*3\s*,\s*1\s*-\s*\(\s*2\s*\*"),                   # Nielsen's max(1/3, 1 - (2ρ - 1)³)
             re.compile(r"\b(nu|ν)\s*\*=?\s*2\b"),                                  # ν doubling
             re.compile(r"\b(mu|lam|lambda_|damping)\w*\s*(\*=|/=|\*|/)\s*(10|nu)\b")]   # Levenberg's ×10 / ÷10
    found = sorted(f.relative_to(PKG).as_posix() for f in PKG.rglob("*.py")
                   if any(rule.search(f.read_text()) for rule in rules))
    assert found == ["core/lm.py"], f"a damping rule outside labutils/core/lm.py: {found}"


def _notebook_imports():
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        for cell in json.loads(nb.read_text())["cells"]:
            if cell["cell_type"] != "code":
                continue
            src = "\n".join(line for line in "".join(cell["source"]).splitlines()
                            if not line.lstrip().startswith(("%", "!")))
            for node in ast.walk(ast.parse(src)):
                if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "labutils":
                    yield nb.name, node.module, [a.name for a in node.names]
                elif isinstance(node, ast.Import):
                    for a in node.names:
                        if a.name.split(".")[0] == "labutils":
                            yield nb.name, a.name, None


def test_notebooks_import_from_the_top_or_one_stage():
    """The one rule for notebooks: ``from labutils import name`` or ``from labutils.<stage> import name``, with
    the name in that package's ``__all__`` (a stage's door, never a room inside it)."""
    stages = set(_stages())
    problems = []
    for nb, module, names in _notebook_imports():
        parts = module.split(".")
        if names is None:
            if module != "labutils":
                problems.append(f"{nb}: import {module} (use from labutils.<stage> import name)")
            continue
        if len(parts) > 2 or (len(parts) == 2 and parts[1] not in stages):
            problems.append(f"{nb}: from {module} import ... (import from labutils or labutils.<stage>)")
            continue
        public = set(importlib.import_module(module).__all__) | (stages if len(parts) == 1 else set())
        problems += [f"{nb}: {n} is not in {module}.__all__" for n in names if n not in public]
    assert not problems, "\n".join(problems)


def test_public_names_resolve():
    for name in labutils.__all__:
        assert getattr(labutils, name) is not None
    with pytest.raises(AttributeError, match="no attribute"):
        labutils.no_such_name  # noqa: B018
    for stage in _stages():
        mod = importlib.import_module(f"labutils.{stage}")
        missing = [n for n in getattr(mod, "__all__", []) if not hasattr(mod, n)]
        assert not missing, f"labutils.{stage}.__all__ names what it does not hold: {missing}"


# Where ``rng`` may be left out, and why: the function draws nothing unless asked to.
RNG_OPTIONAL = {
    "labutils.core.validation.as_rng": "the check of an rng argument itself",
    "labutils.calibrate.chessboard.render_board": "a noise-free drawing by default; noise > 0 without rng raises",
    "labutils.plotting.common.show_reconstruction": "random only for a display subset; else the first max_points",
}


def _every_module():
    return [importlib.import_module(m.name) for m in pkgutil.walk_packages(labutils.__path__, "labutils.")
            if not m.name.endswith("__main__") and m.name.split(".")[1] not in ENTRY_POINTS]


def test_every_module_imports_and_rng_is_keyword_only_and_required():
    """Every module imports; every public function (and public method) with an ``rng`` takes it keyword-only and
    without a default, so no call can fall back to a hidden global state or bind a seed by position."""
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


@pytest.mark.parametrize("cmd", COMMANDS)
def test_command_answers_help_without_warnings(cmd):
    """``python -m labutils.X --help`` exits 0 and prints no RuntimeWarning ('found in sys.modules')."""
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
