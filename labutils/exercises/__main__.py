"""Command line: ``python -m labutils.exercises release OUTDIR [--only NN ...] [--force] [--labutils REQUIREMENT]``.

Writes the student edition of the notebooks into OUTDIR: each notebook as nbgrader's preprocessors make it
(solutions replaced by stubs that raise ``NotImplementedError`` saying what to write, hidden tests removed, outputs
cleared, cells locked; :mod:`labutils.exercises.release`), a ``README.md`` for students and a ``requirements.txt``.
Notebooks without exercises are released as they are, outputs cleared.

OUTDIR is created if its parent exists. Every notebook is converted before anything is written; then all files
are written through temporary files in OUTDIR and ``os.replace``; on any failure none is (and an OUTDIR made by
this run is removed). An OUTDIR that already holds a student edition is refused unless ``--force``.

Exit status 0 on success; 2 with one line ``error: <file>[, cell N]: what is wrong`` on stderr for any failure.
Progress goes to stderr, the summary to stdout.
"""
import sys
from pathlib import Path

from ..core import cli as _cli
from ..data.paths import PROJECT_ROOT
from .release import release_files

NOTEBOOKS = PROJECT_ROOT / "notebooks"


def _select(source, only):
    """The instructor notebooks ``NN_name.ipynb`` in ``source``, or those whose number or name ``only`` gives."""
    source = Path(source)
    if not source.is_dir():
        raise _cli.CommandError(f"{source}: the folder of instructor notebooks does not exist (--source)")
    found = sorted(p for p in source.glob("[0-9][0-9]*_*.ipynb") if p.is_file())
    if not found:
        raise _cli.CommandError(f"{source}: holds no notebooks named NN_name.ipynb (--source)")
    if not only:
        return found
    chosen = []
    for key in only:
        match = [p for p in found if p.name in (key, f"{key}.ipynb") or p.name.split("_")[0] == key]
        if not match:
            raise _cli.CommandError(f"{source}: no notebook {key!r} (--only takes numbers such as 01 or file names; "
                                    f"there are {', '.join(p.name.split('_')[0] for p in found)})")
        chosen += [p for p in match if p not in chosen]
    return chosen


def main(argv=None):
    parser = _cli.Parser(
        prog="python -m labutils.exercises",
        description="Tools for the workbook's exercises.")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_cli.Parser)
    rel = commands.add_parser(
        "release", help="write the student edition of the notebooks (nbgrader's preprocessors)",
        description="Write the student edition of the notebooks into OUTDIR, made by nbgrader's own preprocessors: "
                    "solutions replaced by stubs that say what to write, hidden tests removed, outputs cleared, "
                    "cells locked as nbgrader locks them; with a README.md for students and a requirements.txt.",
        epilog="example: python -m labutils.exercises release handout/ --only 01 02 03")
    rel.add_argument("outdir", metavar="OUTDIR", help="the folder to write into (created if its parent exists)")
    rel.add_argument("--source", default=str(NOTEBOOKS),
                     help="the folder of instructor notebooks (default: this checkout's notebooks/)")
    rel.add_argument("--only", nargs="+", metavar="NN",
                     help="release only these notebooks: numbers (01) or file names (default: all)")
    rel.add_argument("--force", action="store_true", help="replace the files of an earlier student edition in OUTDIR")
    rel.add_argument("--labutils", metavar="REQUIREMENT",
                     help="how students install labutils, a pip requirement written into requirements.txt "
                          "(e.g. \"labutils @ git+https://github.com/ORG/REPO@v1\"); default: a comment")
    rel.add_argument("--quiet", action="store_true", help="no progress, only the summary")
    args = parser.parse_args(argv)
    return release(args)


def release(args):
    outdir = Path(args.outdir)
    notebooks = _select(args.source, args.only)
    progress = _cli.Progress(len(notebooks), "student edition", quiet=args.quiet)
    files, rows = release_files(notebooks, outdir, force=args.force, labutils=args.labutils, progress=progress)
    made = not outdir.exists()
    if made:
        try:
            outdir.mkdir()
        except OSError as exc:
            raise _cli.CommandError(f"{outdir}: cannot make the folder ({exc.strerror or exc})") from None
    try:
        _cli.write_all_atomically(files)
    except (_cli.CommandError, OSError):
        if made:
            try:
                outdir.rmdir()
            except OSError:
                pass
        raise
    width = max(len(name) for name, _ in rows)
    for name, contents in rows:
        print(f"{name:<{width}}  {contents.text()}")
    extra = " and ".join(p.name for p in files if p.suffix != ".ipynb")
    print(f"wrote {len(rows)} student notebook{'s' if len(rows) != 1 else ''} and {extra} to {outdir}")
    if "requirements.txt" not in {p.name for p in files}:
        print("note: no environment.txt found beside the notebooks: no requirements.txt written", file=sys.stderr)
    elif not args.labutils and not args.quiet:
        print("note: requirements.txt does not say where students get labutils (--labutils REQUIREMENT); its last "
              "line asks them to install it as the course says", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
