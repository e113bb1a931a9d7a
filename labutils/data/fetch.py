"""Download the data sets: ``python -m labutils.data fetch NAME|all`` and ``python -m labutils.data list``.

:func:`fetch` downloads each file of a set in the registry (:mod:`labutils.data.registry`) with pooch, checks every
file's sha256, unpacks what the origin packs (the BAL problem comes as ``.bz2``, the Middlebury temple as a
``.zip``) and lays the set out as ``<data>/<name>/<path>``, where ``<data>`` is ``$LABUTILS_DATA`` when set and the
project's ``data/`` folder otherwise: the first places :func:`labutils.data.find_data` searches. A file that
fails its check is never kept, nor a folder made for a set that fails.

``python -m labutils.data fetch`` skips a set already present and verified anywhere on the data path (the course's
shared copy, say) and ends with one line per set: present, fetched, skipped, or failed and why ("offline?" when no
host name resolved).

``$LABUTILS_DATA_URL``: when set, every file is fetched from ``<base>/<name>/<path>`` instead of its origin, for
example from a course server holding the same layout, or (in the tests) a local copy served over HTTP.
"""
import argparse
import os
import shutil
import socket
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

import pooch

from ..core import cli as _cli
from .paths import PROJECT_ROOT, data_dirs
from .registry import DATASETS, FetchError, Source, dataset, file_ok, status

URL_ENV = "LABUTILS_DATA_URL"
TIMEOUT_S = 60          # per request (pooch passes it to requests)
RETRIES = 1             # pooch retries a failed download once, after a short pause
CHUNK = 1 << 16         # download chunk, bytes


# ---------------------------------------------------------------------------------------------------------------
# fetching
# ---------------------------------------------------------------------------------------------------------------
def default_target() -> Path:
    """The folder :func:`fetch` lays data sets out in: ``$LABUTILS_DATA`` if set, else the project's ``data/``.

    Raises
    ------
    FetchError
        If ``$LABUTILS_DATA`` is ``none`` (real data turned off).
    """
    env = os.environ.get("LABUTILS_DATA", "").strip()
    if env.lower() == "none":
        raise FetchError("$LABUTILS_DATA", "is 'none' (real data turned off): unset it, or set it to the folder "
                                           "to fetch into")
    return Path(env).expanduser() if env else PROJECT_ROOT / "data"


def check_target(folder) -> Path:
    """``folder`` as a Path if it is an existing, writable folder, else :class:`FetchError` saying what is wrong."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FetchError(folder, "the data folder does not exist (create it, or set $LABUTILS_DATA to another one)")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise FetchError(folder, "the data folder is not writable")
    return folder


def sources_for(name: str, base_url: str = None) -> tuple:
    """The sources :func:`fetch` tries for a set, in order: only ``base_url`` (or ``$LABUTILS_DATA_URL``) if set.

    >>> [s.url for s in sources_for("chessboard", base_url="http://127.0.0.1:8000/data/")]
    ['http://127.0.0.1:8000/data/chessboard']
    >>> sources_for("dino", base_url="")
    ()
    """
    ds = dataset(name)
    base = os.environ.get(URL_ENV, "").strip() if base_url is None else base_url.strip()
    if base:
        return (Source("files", f"{base.rstrip('/')}/{ds.name}", f"${URL_ENV}"),)
    return ds.sources


@dataclass
class FetchReport:
    """What :func:`fetch` did: the set's folder, how many files it downloaded, and notes on sources that failed."""

    name: str
    folder: Path
    n_downloaded: int
    notes: list


def fetch(name: str, target=None, *, base_url: str = None, progress: bool = True) -> FetchReport:
    """Download a data set, check every file's sha256, and lay it out as ``<target>/<name>/<path>``.

    Files already there with the right sha256 are kept and not downloaded again; a file with the wrong size or
    sha256 is replaced. A download is written to a temporary file next to its destination and moved into place
    only once its sha256 matches: a partial or corrupt download never stays behind, nor does a corrupt old copy
    when no source can replace it, nor a folder this call made and left empty. Sources are tried in order (origin,
    then mirror); the first failure of a source ends its turn and the next takes the remaining files.

    Parameters
    ----------
    name : str
        A key of :data:`DATASETS`.
    target : path, optional
        An existing, writable folder; default :func:`default_target`.
    base_url : str, optional
        Fetch every file from ``<base_url>/<name>/<path>`` instead; default ``$LABUTILS_DATA_URL`` if set.
    progress : bool
        Show a progress line on stderr.

    Returns
    -------
    FetchReport

    Raises
    ------
    FetchError
        One line naming the file: no source known, a download failed (the reason in a phrase: the host did not
        resolve, refused, timed out, answered an HTTP error), a checksum did not match, the disk is full, the target
        folder is missing or not writable. Its ``unresolved`` is True when every source failed because no host name
        resolved. ``KeyError`` for an unknown name.
    """
    ds = dataset(name)
    folder = check_target(default_target() if target is None else target) / ds.name
    sources = sources_for(name, base_url)
    todo = [f for f in ds.files if not file_ok(folder / f.path, f)]
    if todo and not sources:
        raise FetchError(folder / todo[0].path, ds.note)
    for f in todo:                                  # a copy that fails its check is never kept
        _remove(folder / f.path)
    made = sorted({d for f in todo for d in (folder / f.path).parents if (d == folder or folder in d.parents)
                   and not d.exists()}, key=lambda d: -len(d.parts))
    bar = _Progress(ds.name, todo, enabled=progress)
    notes, failures, n_done = [], [], 0
    logger, level = pooch.get_logger(), pooch.get_logger().level
    logger.setLevel("WARNING")                      # pooch logs every file at INFO; the progress line says enough
    try:
        for src in sources:
            if not todo:
                break
            try:
                n_done += _FETCHERS[src.kind](src, folder, todo, bar)
                todo = []
            except FetchError as exc:
                failures.append(exc)
                n_done += sum(1 for f in todo if (folder / f.path).is_file())
                todo = [f for f in todo if not (folder / f.path).is_file()]
                if todo and src is not sources[-1]:
                    notes.append(f"{ds.name}: the {src.role} failed ({exc.message}); trying the next source")
                    bar.note(notes[-1])
    finally:
        logger.setLevel(level)
        bar.close()
        for d in made:                              # the folders this call made and left empty: none stays behind
            try:
                d.rmdir()
            except OSError:
                pass
    if todo:
        failure = failures[-1]
        failure.unresolved = all(e.unresolved for e in failures)
        raise failure
    return FetchReport(ds.name, folder, n_done, notes)


def _file_mode():
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def _remove(path):
    try:
        os.remove(path)
    except FileNotFoundError:
        pass


def _chain(exc):
    """``exc`` and the exceptions behind it (``__cause__``, ``__context__``, urllib3's ``reason``)."""
    seen = []
    while isinstance(exc, BaseException) and exc not in seen:
        seen.append(exc)
        exc = exc.__cause__ or exc.__context__ or getattr(exc, "reason", None)
    return seen


def _shorten(text, limit=160):
    """``text`` on one line, cut at a word boundary with '...' if longer than ``limit``."""
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[:limit].rsplit(" ", 1)[0] + " ..."


def _reason(exc, url):
    """``(why, unresolved)`` for a failed download: a short phrase (not a library's raw text cut mid-word), and
    whether the host's name did not resolve (no network, or no such host)."""
    chain = _chain(exc)
    names = {type(e).__name__ for e in chain}
    host = urlsplit(url).hostname or url
    response = getattr(exc, "response", None)
    if getattr(response, "status_code", None) is not None:
        return f"the server answered HTTP {response.status_code} {response.reason or ''}".rstrip(), False
    if any(isinstance(e, socket.gaierror) for e in chain) or "NameResolutionError" in names:
        return f"cannot resolve the host {host}", True
    if any(isinstance(e, ConnectionRefusedError) for e in chain):
        return f"{host} refused the connection", False
    if any(isinstance(e, TimeoutError) for e in chain) or any("Timeout" in n for n in names):
        return f"{host} did not answer within {TIMEOUT_S} s", False
    if any(isinstance(e, ConnectionError) for e in chain) or "ConnectionError" in names:
        return f"the connection to {host} failed", False
    return f"{type(chain[-1]).__name__}: {_shorten(chain[-1])}", False


def _failed(dest, exc, url):
    """The :class:`FetchError` for a failed download of ``dest`` from ``url``: one line, the reason in a phrase."""
    if "does not match the known hash" in str(exc):
        return FetchError(dest, f"sha256 mismatch: {url} did not serve the registered file (corrupt or changed); "
                                "nothing was kept")
    why, unresolved = _reason(exc, url)
    return FetchError(dest, f"download from {url} failed: {why}", unresolved=unresolved)


def _downloader(bar, label):
    return pooch.HTTPDownloader(progressbar=bar.file(label), chunk_size=CHUNK, timeout=TIMEOUT_S)


def _fetch_files(src, folder, todo, bar):
    """Each file at ``src.url/<path>``, checked by pooch against its sha256 before it is moved into place."""
    reg = pooch.create(path=folder, base_url=src.url + "/", registry={f.path: f"sha256:{f.sha256}" for f in todo},
                       retry_if_failed=RETRIES)
    mode = _file_mode()
    for f in todo:
        dest = folder / f.path
        try:
            reg.fetch(f.path, downloader=_downloader(bar, f.path))
            os.chmod(dest, mode)                    # pooch's temporary file was 0600
        except Exception as exc:                    # network, HTTP status, checksum (ValueError), disk (OSError)
            _remove(dest)
            raise _failed(dest, exc, src.url_of(f.path)) from exc
        bar.done_file(f)
    return len(todo)


def _fetch_bz2(src, folder, todo, bar):
    """Each file bzip2-compressed at ``src.url/<path>.bz2``: pooch downloads and decompresses, we check."""
    mode = _file_mode()
    for f in todo:
        dest = folder / f.path
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = tempfile.mkdtemp(prefix=".fetch-", dir=dest.parent)
        try:
            name = Path(f.path).name
            try:
                out = pooch.retrieve(src.url_of(f.path), known_hash=None, fname=name + ".bz2", path=tmp,
                                     processor=pooch.Decompress(method="bzip2", name=name),
                                     downloader=_downloader(bar, f.path + ".bz2"))
            except Exception as exc:
                raise _failed(dest, exc, src.url_of(f.path)) from exc
            _place(out, dest, f, src.url_of(f.path), mode)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        bar.done_file(f)
    return len(todo)


def _fetch_zip(src, folder, todo, bar):
    """One archive at ``src.url``: pooch downloads it and unzips the members we need, we check each."""
    folder.mkdir(parents=True, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix=".fetch-", dir=folder)
    mode = _file_mode()
    try:
        members = [src.member_prefix + f.path for f in todo]
        try:
            pooch.retrieve(src.url, known_hash=None, fname="archive.zip", path=tmp,
                           processor=pooch.Unzip(members=members, extract_dir="unzipped"),
                           downloader=_downloader(bar, src.url.rsplit("/", 1)[-1]))
        except Exception as exc:
            raise _failed(folder / todo[0].path, exc, src.url) from exc
        for f, member in zip(todo, members):
            _place(Path(tmp) / "unzipped" / member, folder / f.path, f, src.url_of(f.path), mode)
            bar.done_file(f)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return len(todo)


def _place(src_path, dest, entry, url, mode):
    """Move an unpacked file into place if its size and sha256 match ``entry``; else FetchError."""
    src_path = Path(src_path)
    if not src_path.is_file():
        raise FetchError(dest, f"{url}: not in the archive")
    if not file_ok(src_path, entry):
        raise FetchError(dest, f"sha256 mismatch: {url} did not unpack to the registered file (corrupt or changed); "
                               "nothing was kept")
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.chmod(src_path, mode)
        os.replace(src_path, dest)
    except OSError as exc:
        _remove(dest)
        raise FetchError(dest, f"cannot write: {exc.strerror or exc}") from exc


_FETCHERS = {"files": _fetch_files, "bz2": _fetch_bz2, "zip": _fetch_zip}


class _Progress:
    """One progress line on stderr per data set, redrawn in place on a terminal (pooch drives it per download)."""

    def __init__(self, name, todo, enabled=True, stream=None):
        self.stream = stream or sys.stderr
        self.enabled = enabled and bool(todo)
        self.live = self.enabled and self.stream.isatty()
        self.name, self.n_files, self.total = name, len(todo), sum(f.size for f in todo)
        self.files_done, self.bytes_done, self.current, self.last = 0, 0, None, 0.0
        if self.enabled and not self.live:
            print(f"{name}: fetching {_files(self.n_files)}, {_mb(self.total)} ...", file=self.stream, flush=True)

    def file(self, label):
        return _FileBar(self, label) if self.enabled else False

    def done_file(self, entry):
        self.files_done += 1
        self.bytes_done += entry.size
        self.draw(force=True)

    def note(self, text):
        if self.enabled:
            print(("\r" if self.live else "") + f"note: {text}", file=self.stream, flush=True)

    def draw(self, extra=0, label="", force=False):
        now = time.monotonic()
        if not self.live or (not force and now - self.last < 0.1):
            return
        self.last = now
        frac = min(1.0, (self.bytes_done + extra) / max(self.total, 1))
        line = (f"{self.name}: [{'#' * int(30 * frac):<30}] {self.files_done}/{self.n_files} files, "
                f"{_mb(self.bytes_done + extra)} of {_mb(self.total)}  {label}")
        print("\r" + line[:110].ljust(110), end="", file=self.stream, flush=True)

    def close(self):
        if self.live:
            print(file=self.stream, flush=True)


class _FileBar:
    """pooch's custom progress bar interface (``total``, ``update``, ``reset``, ``close``) for one download."""

    def __init__(self, parent, label):
        self.parent, self.label, self.total, self.n = parent, label, 0, 0

    def update(self, k):
        self.n += k
        self.parent.draw(min(self.n, self.total or self.n), self.label)

    def reset(self):
        self.n = 0

    def close(self):
        pass


def _mb(n):
    return f"{n / 1e6:.1f} MB"


def _files(n):
    return f"{n} file" + ("s" if n != 1 else "")


# ---------------------------------------------------------------------------------------------------------------
# the command line
# ---------------------------------------------------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    def error(self, message):                   # one line, exit status 2 (argparse's default prints the usage too)
        self.exit(2, f"error: {message} (see {self.prog} --help)\n")


def _format_status(ds, st):
    if st.state == "present":
        return f"present in {st.folder} (sha256 verified)"
    if st.state == "missing":
        return "missing"
    parts = [f"{len(st.missing)} of {len(ds.files)} files missing"] if st.missing else []
    parts += [f"{len(st.corrupt)} corrupt ({', '.join(st.corrupt[:3])}{', ...' if len(st.corrupt) > 3 else ''})"
              ] if st.corrupt else []
    return f"incomplete in {st.folder}: {'; '.join(parts)}"


def _list(names, show_files):
    dirs = data_dirs()
    print("data path, in order: " + (", ".join(map(str, dirs)) or "(none: $LABUTILS_DATA=none or no folder exists)"))
    try:
        print(f"fetch target: {default_target()}")
    except FetchError as exc:
        print(f"fetch target: none ({exc})")
    base = os.environ.get(URL_ENV, "").strip()
    if base:
        print(f"${URL_ENV}: every file is fetched from {base.rstrip('/')}/<set>/<path>")
    for name in names:
        ds = DATASETS[name]
        st = status(name, dirs)
        print(f"\n{name:<13} {_files(len(ds.files)):>9} {_mb(ds.n_bytes):>9}  {_format_status(ds, st)}")
        print(f"    {ds.title}")
        print(f"    licence: {ds.licence}; cite: {ds.citation}")
        print(f"    from: {ds.origin}")
        srcs = sources_for(name)
        print("    download: " + ("; ".join(f"{s.role} {s.url}" for s in srcs) if srcs else "none known: " + ds.note))
        if show_files:
            for f in ds.files:
                print(f"      {f.path:<36} {f.size:>9}  {f.sha256}  " + " | ".join(s.url_of(f.path) for s in srcs))
    return 0


def present_on_path(name, dirs=None):
    """The folders the loaders would read a data set from, if every file of it is verified there, else None.

    Each file is judged where :func:`labutils.data.find_data` would find it: in the first folder of the data path
    that has it. The set is present when each such copy has its registered size and sha256.

    Returns
    -------
    list of Path or None
        The set's folders holding those copies (one, usually), in data-path order.
    """
    ds = dataset(name)
    dirs = data_dirs() if dirs is None else dirs
    used = []
    for f in ds.files:
        found = next((Path(d) / ds.name for d in dirs if (Path(d) / ds.name / f.path).exists()), None)
        if found is None or not file_ok(found / f.path, f):
            return None
        used += [found] if found not in used else []
    return used


def _fetch(names, explicit, force=False):
    """Fetch each set; then one line per set, in order: present, fetched (stdout), skipped (a note) or failed and
    why (an ``error:`` line on stderr). Returns the exit status: 2 if any set failed."""
    try:
        target = check_target(default_target())
    except FetchError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    lines, failures, n_downloaded = [], [], 0
    for name in names:
        ds = DATASETS[name]
        where = None if force else present_on_path(name)
        if where:
            lines.append((sys.stdout, f"{name}: present in {', '.join(map(str, where))} (sha256 verified); "
                                      "nothing downloaded"))
            continue
        if not explicit and not sources_for(name):
            lines.append((sys.stderr, f"note: {name}: skipped, {ds.note}"))
            continue
        try:
            rep = fetch(name, target)
        except FetchError as exc:
            failures.append(exc)
            lines.append((sys.stderr, exc))
            continue
        n_downloaded += rep.n_downloaded
        lines.append((sys.stdout, f"{name}: {_files(len(ds.files))}, {_mb(ds.n_bytes)}, sha256 verified, in "
                                  f"{rep.folder} ({rep.n_downloaded} downloaded)"))
    offline = bool(failures) and n_downloaded == 0 and all(e.unresolved for e in failures)
    for stream, line in lines:
        if isinstance(line, FetchError):
            line = f"error: {line}" + (" (offline? no host name resolved)" if offline else "")
        print(line, file=stream, flush=True)
    return 2 if failures else 0


def main(argv=None) -> int:
    """``python -m labutils.data list [NAME ...] [--files]`` and ``python -m labutils.data fetch NAME ...|all``.

    ``fetch`` skips a set already present and verified on the data path (:func:`present_on_path`), unless
    ``--force``, and ends with one line per set: present, fetched (stdout), skipped (a note) or failed and why
    (stderr, ``error: <file>: what went wrong``, with "offline?" when no host name resolved). A set that fails
    leaves nothing behind: no partial file, no folder made for it. ``fetch all`` skips, with a note, the sets
    that have no public download unless ``$LABUTILS_DATA_URL`` is set; naming such a set is an error.

    Exit status 0 on success; 2 when an argument is wrong or a data set could not be laid out. A Ctrl-C raises
    ``KeyboardInterrupt`` (no partial file and no folder made for the set is kept), which the command line,
    :func:`labutils.core.cli.run`, reports on one line with exit status 130.
    """
    names = list(DATASETS)
    parser = _Parser(prog="python -m labutils.data",
                     description="Fetch the workbook's data sets from their public origins (sha256-checked) and "
                                 "list what is on the data path.",
                     epilog=f"Data sets: {', '.join(names)}. Files go to $LABUTILS_DATA if set, else the project's "
                            f"data/ folder. ${URL_ENV}=<base> fetches every file from <base>/<set>/<path> instead "
                            "of its origin.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="{fetch,list}")
    p_fetch = sub.add_parser("fetch", help="download, verify and lay out data sets",
                             description="Download data sets, check every file's sha256, and lay them out on the "
                                         "data path. A set already present and verified on the data path is "
                                         "skipped; files already in the target and verified are not downloaded "
                                         "again. Ends with one line per set.")
    p_fetch.add_argument("names", nargs="+", metavar="NAME", help=f"data sets: {', '.join(names)}, or all")
    p_fetch.add_argument("--force", action="store_true",
                         help="fetch into the target folder even a set that is present elsewhere on the data path "
                              "(files already verified in the target are still not downloaded again)")
    p_list = sub.add_parser("list", help="show each data set, its size, licence and whether it is present",
                            description="Show each data set, its size, licence and citation, its sources, and "
                                        "whether it is on the data path (every file's sha256 is checked).")
    p_list.add_argument("names", nargs="*", metavar="NAME", help="data sets to show (default: all)")
    p_list.add_argument("--files", action="store_true", help="also list every file: size, sha256, URLs")
    args = parser.parse_args(argv)

    unknown = [n for n in args.names if n not in names and not (args.command == "fetch" and n == "all")]
    if unknown:
        choices = ", ".join(names + (["all"] if args.command == "fetch" else []))
        print(f"error: unknown data set {unknown[0]!r}; choose from {choices}", file=sys.stderr)
        return 2
    if args.command == "list":
        return _list(args.names or names, args.files)
    explicit = "all" not in args.names
    return _fetch(names if not explicit else list(dict.fromkeys(args.names)), explicit, args.force)


if __name__ == "__main__":
    sys.exit(_cli.run(main))
