"""What every command line of the workbook shares: one-line errors with exit status 2, output written atomically
with the usual file mode, the output folder checked before any work, and progress on stderr.

Each ``python -m labutils.<command>`` raises :class:`CommandError` (or ``ValueError``/``OSError`` from the
library, which already name the file and line) and lets :func:`run` turn it into ``error: ...`` on stderr with
exit status 2 — never a traceback.
"""
import os
import sys
import tempfile
import time
from pathlib import Path


class CommandError(Exception):
    """A failure to report on one line (it names the file, and the line where there is one)."""


def run(main, argv=None):
    """Call ``main(argv)``; report ``CommandError``, ``ValueError`` and ``OSError`` as one line, exit status 2.

    Returns the exit status (0 on success, or what ``main`` returned).
    """
    try:
        status = main(argv)
    except (CommandError, ValueError, OSError) as exc:
        message = str(exc).strip().splitlines()
        print(f"error: {message[0] if message else type(exc).__name__}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 2
    return 0 if status is None else int(status)


def check_output_path(path, what="output"):
    """Fail early (before any work) when ``path`` cannot be written: its folder is missing or it is a folder.

    Returns ``Path(path)``.
    """
    path = Path(path)
    if path.is_dir():
        raise CommandError(f"{path}: the {what} path is a folder; give a file name")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise CommandError(f"{path}: the folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise CommandError(f"{path}: the folder {folder} is not writable")
    return path


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_atomically(path, data):
    """Write ``data`` (str or bytes) to ``path`` through a temporary file in the same folder, then rename.

    The file gets the usual mode (``0o666 & ~umask``, i.e. 0644 under umask 022); on any failure (disk full,
    file too large, a folder in the way) the temporary file is removed, nothing is left behind, and the error
    names ``path``.
    """
    path = Path(path)
    mode = "wb" if isinstance(data, (bytes, bytearray)) else "w"
    fd, tmp = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as f:
            f.write(data)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise CommandError(f"{path}: cannot write ({exc.strerror or exc})") from None
        raise


class Progress:
    """A progress bar on stderr: ``label [#####.....] 5/10 1.2 s`` redrawn in place on a terminal, and printed
    at about every fifth of the way elsewhere (so a log or a notebook still shows where the work is)."""

    def __init__(self, total, label="", stream=None, width=30):
        self.total, self.label, self.n, self.width = max(int(total), 1), label, 0, width
        self.stream = sys.stderr if stream is None else stream
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.every = max(1, self.total // 5)
        self.tic = time.perf_counter()

    def step(self, n=1):
        self.n = min(self.n + n, self.total)
        if self.tty or self.n % self.every == 0 or self.n == self.total:
            filled = int(self.width * self.n / self.total)
            line = (f"{self.label} [{'#' * filled}{'.' * (self.width - filled)}] {self.n}/{self.total} "
                    f"{time.perf_counter() - self.tic:.1f} s")
            end = "\n" if (self.n == self.total or not self.tty) else ""
            print(("\r" if self.tty else "") + line, end=end, file=self.stream, flush=True)
