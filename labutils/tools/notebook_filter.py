"""One-time setup of a clone: git stores notebooks without outputs, so running and saving one changes nothing.

Run it once in your clone, with the workbook's virtual environment active::

    python -m labutils.tools.notebook_filter

It runs ``nbstripout --install --attributes .gitattributes``, which registers the git filter ``nbstripout`` in
``.git/config`` (calling this environment's Python; ``.gitattributes`` already routes ``*.ipynb`` through it), and
then sets the two things that command has no option for:

- ``--keep-id`` on the filter: JupyterLab keeps cell ids stable; nbstripout would otherwise renumber them and
  rewrite every notebook once;
- ``filter.nbstripout.extrakeys``: also drop the language metadata (``metadata.language_info``, with the Python
  version) that JupyterLab rewrites on every save. The kernel (``metadata.kernelspec``: ``python3``) is kept: without
  it JupyterLab opens every notebook with a "Select Kernel" dialog.

From then on ``git diff`` compares notebooks without outputs, execution counts or the language metadata (a notebook you
ran and saved shows no change), and ``git add`` stores them stripped. Your working copy keeps its outputs.
``git status`` may still list a notebook you only ran and saved as modified: git sees the file's size change before
it asks the filter (a limit of git's clean filters); ``git add`` it, and ``git status`` has nothing to commit.
``--check`` exits 1 if the filter is not set up like this; ``--uninstall`` removes it.
"""
import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EXTRA_KEYS = ["metadata.language_info"]     # rewritten by JupyterLab on every save (the kernelspec is kept)
CLEAN_FLAGS = ["--keep-id"]
# nbstripout 0.9's own default keys (in its main()); with EXTRA_KEYS, what the filter drops besides outputs and counts
NBSTRIPOUT_DEFAULT_KEYS = ["metadata.signature", "metadata.widgets", "cell.metadata.collapsed",
                           "cell.metadata.ExecuteTime", "cell.metadata.execution", "cell.metadata.heading_collapsed",
                           "cell.metadata.hidden", "cell.metadata.scrolled"]


def _git(*args, check=True):
    proc = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)
    if check and proc.returncode != 0:
        raise SystemExit(f"error: git {' '.join(args)}: {proc.stderr.strip() or 'failed'}")
    return proc.stdout.strip()


def _config(key):
    return _git("config", "--local", "--get", key, check=False)


def is_set_up():
    """True if the filter runs nbstripout with --keep-id and the extra keys, and .gitattributes routes notebooks."""
    clean, keys = _config("filter.nbstripout.clean"), _config("filter.nbstripout.extrakeys").split()
    attrs = _git("check-attr", "filter", "--", "notebooks/x.ipynb")
    return ("nbstripout" in clean and all(f in clean.split() for f in CLEAN_FLAGS)
            and all(k in keys for k in EXTRA_KEYS) and attrs.endswith(": nbstripout"))


def install():
    subprocess.run([sys.executable, "-m", "nbstripout", "--install", "--attributes", ".gitattributes"],
                   cwd=ROOT, check=True)
    for key in ("filter.nbstripout.clean", "diff.ipynb.textconv"):
        cmd = _config(key)
        if cmd and not all(f in cmd.split() for f in CLEAN_FLAGS):
            _git("config", "--local", key, " ".join([cmd, *CLEAN_FLAGS]))
    _git("config", "--local", "filter.nbstripout.extrakeys", " ".join(EXTRA_KEYS))


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m labutils.tools.notebook_filter",
                                     description="Set up the git filter that stores notebooks without outputs.")
    action = parser.add_mutually_exclusive_group()
    action.add_argument("--check", action="store_true", help="exit 1 if the filter is not set up")
    action.add_argument("--uninstall", action="store_true", help="remove the filter from .git/config")
    args = parser.parse_args(argv)
    if not (ROOT / ".git").exists():
        print(f"error: {ROOT}: not a git clone (nothing to set up)", file=sys.stderr)
        return 2
    if args.check:
        ok = is_set_up()
        print("the notebook filter is set up" if ok else
              "the notebook filter is not set up: run python -m labutils.tools.notebook_filter")
        return 0 if ok else 1
    try:
        import nbstripout  # noqa: F401
    except ImportError:
        print("error: nbstripout is not installed in this environment: pip install -r environment.txt",
              file=sys.stderr)
        return 2
    if args.uninstall:
        subprocess.run([sys.executable, "-m", "nbstripout", "--uninstall"], cwd=ROOT, check=True)
        _git("config", "--local", "--unset", "filter.nbstripout.extrakeys", check=False)
        print("removed the notebook filter from .git/config (.gitattributes still names it; git ignores it now)")
        return 0
    install()
    if not is_set_up():
        print("error: .git/config: the filter was not set up as expected; see git config --get-regexp nbstripout",
              file=sys.stderr)
        return 2
    print(f"notebook filter set up in {ROOT / '.git'}: git stores notebooks without outputs, execution counts or "
          "kernel metadata;\nyour working copies keep their outputs, `git diff` ignores them, and `git add` clears a "
          "notebook that `git status` lists only because you ran it.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
