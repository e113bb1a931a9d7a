"""Where the real data lives: the data path, and a clear message when a data set is missing.

The data path is searched in this order:

1. ``$LABUTILS_DATA`` (a folder; the value ``none`` turns real data off, as on a fresh clone),
2. the project's own ``data/`` folder,
3. ``../shared/data/`` beside the project's root.

Real data is never committed. ``python -m labutils.data fetch NAME`` downloads a data set into the first of
these folders (see :mod:`labutils.data.fetch`); the dinosaur has no public download, so the course provides its
copy (:func:`how_to_get` says so).
"""
import os
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[2]
COURSE_ONLY = ("dino",)     # the sets with no public download (no sources in labutils.data.registry)


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


def how_to_get(name):
    """One sentence saying how to get data set ``name``: the command that fetches it, or, for a set with no public
    download (the dinosaur) while ``$LABUTILS_DATA_URL`` is unset, where the course's copy comes from.

    >>> how_to_get("bal")
    'Fetch it with:  python -m labutils.data fetch bal'
    >>> import os; old = os.environ.pop("LABUTILS_DATA_URL", None)
    >>> how_to_get("dino").split(". ")[0]
    'The dino set has no public download: your course provides its copy'
    >>> _ = os.environ.update(LABUTILS_DATA_URL=old) if old is not None else None
    """
    if name in COURSE_ONLY and not os.environ.get("LABUTILS_DATA_URL", "").strip():
        return (f"The {name} set has no public download: your course provides its copy. Copy the course's "
                f"{name}/ folder into data/ (or use the course's shared ../shared/data/ beside the project), or "
                f"fetch it from the course's server (LABUTILS_DATA_URL=<the course's address> python -m labutils.data "
                f"fetch {name})")
    return f"Fetch it with:  python -m labutils.data fetch {name}"


def missing_message(relpath, help_text=None):
    """The message of :class:`DataNotFoundError` for ``relpath``: each folder searched, in order, and how to get
    the data set (the first component of ``relpath``; :func:`how_to_get`)."""
    name = Path(relpath).parts[0]
    lines = [f"{relpath} is not on the data path. Searched, in order:"]
    for d, origin in candidate_dirs():
        if d is None:
            lines.append(f"  - (nothing: {origin})")
        else:
            lines.append(f"  - {d}  ({origin}{'' if d.is_dir() else '; does not exist'})")
    lines.append(how_to_get(name) + "   (python -m labutils.data list shows every data set)")
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
