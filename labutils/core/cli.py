"""What every command line of the workbook shares: one-line errors with exit status 2, output written atomically
with the usual file mode, the outputs checked before any work (their folder, and that none is an input or another
output), a Ctrl-C reported on one line, and progress on stderr.

Each ``python -m labutils.<command>`` raises :class:`CommandError` (or ``ValueError``/``OSError`` from the
library, which already name the file and line) and lets :func:`run` turn it into ``error: ...`` on stderr with
exit status 2 — never a traceback.

A Ctrl-C is one line, ``error: interrupted``, with exit status 130 (128 + SIGINT, what a shell reports for a
command that SIGINT stopped, so that a script can tell an interruption from a failure), and nothing half-written:
every output goes to a temporary file that is removed. That holds while ``python -m labutils.<command>`` is still
importing numpy and scipy: the handler that ``labutils/__init__.py`` installs for ``-m`` runs says the same and
exits (only Python's own start-up, its first few hundredths of a second, comes before it); :func:`run` then hands
Ctrl-C back to Python as ``KeyboardInterrupt`` and reports it.
"""
import argparse
import os
import signal
import sys
import tempfile
import time
from pathlib import Path

INTERRUPTED = 130        # the exit status after a Ctrl-C: 128 + SIGINT, as a shell reports it


class CommandError(Exception):
    """A failure to report on one line (it names the file, and the line where there is one)."""


def run(main, argv=None):
    """Call ``main(argv)``; report ``CommandError``, ``ValueError`` and ``OSError`` as one line, exit status 2, and
    a Ctrl-C (``KeyboardInterrupt``) as ``error: interrupted``, exit status :data:`INTERRUPTED` (130).

    Returns the exit status (0 on success, or what ``main`` returned).
    """
    try:
        _take_back_ctrl_c()
        status = main(argv)
    except (CommandError, ValueError, OSError) as exc:
        message = str(exc).strip().splitlines()
        print(f"error: {message[0] if message else type(exc).__name__}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr, flush=True)
        return INTERRUPTED
    return 0 if status is None else int(status)


def _take_back_ctrl_c():
    """Ctrl-C raises ``KeyboardInterrupt`` again, if the loading-time handler of ``labutils/__init__.py`` has it."""
    try:
        if getattr(signal.getsignal(signal.SIGINT), "__name__", "") == "_interrupted_while_loading":
            signal.signal(signal.SIGINT, signal.default_int_handler)
    except ValueError:                  # not the main thread: signals are not ours to set
        pass


def _same_file(a, b):
    try:
        return os.path.samefile(a, b)           # also through hard links
    except OSError:                             # one of them does not exist (yet): compare where they resolve to
        return os.path.realpath(a) == os.path.realpath(b)


def check_distinct(outputs, inputs=()):
    """Refuse, before any work, an output that is one of the inputs or another output.

    Files are compared as the system sees them (``os.path.samefile``: the same file through a symbolic or hard
    link, or another spelling of the path), or by resolved path (``os.path.realpath``) where a file does not
    exist yet.

    Parameters
    ----------
    outputs, inputs : iterable of (path, str)
        Each file with what it is on the command line (``"--out"``, ``"the track file"``); ``None`` paths are
        skipped.

    Raises
    ------
    CommandError
        One line naming the output and what it would overwrite, e.g.
        ``tracks.txt: --out is the track file (tracks.txt); it would be overwritten: choose another file``.

    Examples
    --------
    >>> check_distinct([("a.ply", "--ply")], [("b.txt", "the tracks")])
    >>> check_distinct([("r.json", "--out"), ("./r.json", "--ply")])
    Traceback (most recent call last):
    ...
    labutils.core.cli.CommandError: ./r.json: --ply and --out name the same file (r.json); give each its own file
    """
    inputs = [(p, what) for p, what in inputs if p is not None]
    seen = []
    for path, what in outputs:
        if path is None:
            continue
        for src, src_what in inputs:
            if _same_file(path, src):
                raise CommandError(f"{path}: {what} is {src_what} ({src}); it would be overwritten: choose another "
                                   "file")
        for other, other_what in seen:
            if _same_file(path, other):
                raise CommandError(f"{path}: {what} and {other_what} name the same file ({other}); give each its "
                                   "own file")
        seen.append((path, what))


def seed_arg(text):
    """The argparse ``type`` of ``--seed``: a non-negative integer (what ``numpy.random.default_rng`` takes).

    >>> seed_arg("7")
    7
    >>> seed_arg("-1")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: must be a non-negative integer; got '-1'
    """
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a non-negative integer; got {text!r}")
    return value


def check_output_path(path, what=None):
    """Fail early (before any work) when ``path`` cannot be written: its folder is missing or it is a folder.

    Returns ``Path(path)``.
    """
    path = Path(path)
    tail = f" ({what})" if what else ""
    if path.is_dir():
        raise CommandError(f"{path}: is a folder; give a file name{tail}")
    if path.exists() and not os.access(path, os.W_OK):
        raise CommandError(f"{path}: the file exists and is not writable{tail}")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise CommandError(f"{path}: the folder {folder} does not exist{tail}")
    if not os.access(folder, os.W_OK):
        raise CommandError(f"{path}: the folder {folder} is not writable{tail}")
    return path


class Parser(argparse.ArgumentParser):
    """argparse, with a bad argument reported on one line (``error: ...``, exit status 2) like every failure."""

    def error(self, message):
        self.exit(2, f"error: {message} (see --help)\n")


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_all_atomically(outputs):
    """Write ``{path: str or bytes}``, each to a temporary file in its folder, then ``os.replace`` them all.

    On any failure (disk full, file too large, permissions, a Ctrl-C) every temporary file is removed, nothing is
    replaced, and the ``OSError`` raised names the path. The files get the usual mode ``0o666 & ~umask`` (0644 under
    umask 022).
    """
    mode = 0o666 & ~_umask()
    temps, target = [], None
    try:
        for target, data in outputs.items():
            p = Path(target)
            fd, tmp = tempfile.mkstemp(dir=p.parent if str(p.parent) else ".", prefix=f".{p.name}.", suffix=".tmp")
            temps.append((tmp, target))
            with os.fdopen(fd, "wb") as fh:
                fh.write(data.encode() if isinstance(data, str) else data)
                fh.flush()
                os.fsync(fh.fileno())
            os.chmod(tmp, mode)
        for tmp, target in temps:
            os.replace(tmp, target)
    except BaseException as exc:                # an OSError, or a Ctrl-C: remove the temporary files either way
        for tmp, _ in temps:
            try:
                os.remove(tmp)
            except OSError:
                pass
        if isinstance(exc, OSError):
            raise OSError(f"{target}: cannot write ({exc.strerror or exc})") from None
        raise


def write_atomically(path, data):
    """Write one file the way :func:`write_all_atomically` does."""
    write_all_atomically({path: data})


class Progress:
    """A progress bar on stderr: ``label [#####.....] 5/10 1.2 s note`` redrawn in place on a terminal; elsewhere (a
    log, CI) one line at about every fifth of the way, and every line that carries a note. Silent with ``quiet``."""

    def __init__(self, total, label="", *, quiet=False, stream=None, width=20):
        self.total, self.label, self.n, self.width, self.quiet = max(int(total), 1), label, 0, width, quiet
        self.stream = sys.stderr if stream is None else stream
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.every = max(1, self.total // 5)
        self.tic = time.perf_counter()

    def step(self, n=1, note=""):
        """Advance by ``n``; ``note`` (e.g. "board not found, skipped") is shown with the bar."""
        self.n = min(self.n + n, self.total)
        if self.quiet or not (self.tty or note or self.n % self.every == 0 or self.n == self.total):
            return
        filled = int(self.width * self.n / self.total)
        line = (f"{self.label} [{'#' * filled}{'.' * (self.width - filled)}] {self.n}/{self.total} "
                f"{time.perf_counter() - self.tic:.1f} s" + (f" {note}" if note else ""))
        if self.tty:
            print(f"\r\033[K{line}", end="\n" if self.n == self.total else "", file=self.stream, flush=True)
        else:
            print(line, file=self.stream, flush=True)

    def note(self, text):
        """A line of its own (a warning, a stage)."""
        if not self.quiet:
            print(("\r\033[K" if self.tty else "") + text, file=self.stream, flush=True)
