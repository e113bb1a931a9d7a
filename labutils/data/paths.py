"""Where the real data lives: the data path, and a clear message when a data set is missing.

The data path is searched in this order:

1. ``$LABUTILS_DATA`` (a folder; the value ``none`` turns real data off, as on a fresh clone),
2. the project's own ``data/`` folder,
3. ``../shared/data/`` beside the project's root.

Real data is never committed. ``python -m labutils.data fetch NAME`` downloads a data set into the first of
these folders (see :mod:`labutils.data.fetch`).
"""
import os
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[2]


class DataNotFoundError(FileNotFoundError):
    """A real data set is not on the data path; the message says what is missing, where it was looked for, and
    the command that fetches it."""


def candidate_dirs():
    """The folders of the data path, in search order, whether they exist or not, with why each is there.

    Returns
    -------
    list of (Path or None, str)
        ``(folder, origin)``; the folder is None where ``$LABUTILS_DATA=none`` switched real data off.

    Examples
    --------
    >>> import os; old = os.environ.pop("LABUTILS_DATA", None)
    >>> [origin for _, origin in candidate_dirs()]
    ["the project's data/ folder", '../shared/data beside the project']
    >>> os.environ["LABUTILS_DATA"] = "none"
    >>> candidate_dirs()
    [(None, '$LABUTILS_DATA=none (real data switched off)')]
    >>> _ = os.environ.pop("LABUTILS_DATA") if old is None else os.environ.update(LABUTILS_DATA=old)
    """
    env = os.environ.get("LABUTILS_DATA", "").strip()
    if env.lower() == "none":
        return [(None, "$LABUTILS_DATA=none (real data switched off)")]
    out = [(Path(env).expanduser(), "$LABUTILS_DATA")] if env else []
    return out + [(PROJECT_ROOT / "data", "the project's data/ folder"),
                  (PROJECT_ROOT.parent / "shared" / "data", "../shared/data beside the project")]


def data_dirs():
    """The folders searched for real data, in order: those of :func:`candidate_dirs` that exist.

    >>> import os; old = os.environ.get("LABUTILS_DATA")
    >>> os.environ["LABUTILS_DATA"] = "none"
    >>> data_dirs()
    []
    >>> _ = os.environ.pop("LABUTILS_DATA") if old is None else os.environ.update(LABUTILS_DATA=old)
    """
    return [d for d, _ in candidate_dirs() if d is not None and d.is_dir()]


def missing_message(relpath, help_text=None):
    """The message of :class:`DataNotFoundError` for ``relpath``: each folder searched, in order, and the
    command that fetches the data set (the first component of ``relpath``)."""
    name = Path(relpath).parts[0]
    lines = [f"{relpath} is not on the data path. Searched, in order:"]
    for d, origin in candidate_dirs():
        if d is None:
            lines.append(f"  - (nothing: {origin})")
        else:
            lines.append(f"  - {d}  ({origin}{'' if d.is_dir() else '; does not exist'})")
    lines.append(f"Fetch it with:  python -m labutils.data fetch {name}   (python -m labutils.data list shows "
                 "every data set)")
    if help_text:
        lines.append(help_text)
    return "\n".join(lines)


def find_data(relpath, help_text=None):
    """Path of ``relpath`` in the first data folder that has it, else :class:`DataNotFoundError`.

    Examples
    --------
    >>> find_data("no-such-set/file.txt")
    Traceback (most recent call last):
    ...
    labutils.data.paths.DataNotFoundError: no-such-set/file.txt is not on the data path. Searched, in order:
    ...
    """
    for d in data_dirs():
        p = d / relpath
        if p.exists():
            return p
    raise DataNotFoundError(missing_message(relpath, help_text))


def has_data(relpath):
    """True if ``relpath`` is on the data path.

    >>> has_data("no-such-set/file.txt")
    False
    """
    try:
        find_data(relpath)
        return True
    except DataNotFoundError:
        return False
