"""The PLY header: the type names, the records of elements and properties, and the header's rules."""
import re
from dataclasses import dataclass, field

import numpy as np

PLY_TYPES = {
    "char": "i1", "uchar": "u1", "short": "i2", "ushort": "u2", "int": "i4", "uint": "u4", "float": "f4",
    "double": "f8", "int8": "i1", "uint8": "u1", "int16": "i2", "uint16": "u2", "int32": "i4", "uint32": "u4",
    "float32": "f4", "float64": "f8",
}
"""PLY type names (standard and alias) → numpy type codes (without byte order)."""

_NAME_OF = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "u4": "uint",
            "f4": "float", "f8": "double"}
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}


@dataclass
class PlyProperty:
    """One property of an element: ``property <type> <name>`` or ``property list <count> <item> <name>``."""

    name: str
    type: str                      # PLY type name of the value (of the items, for a list)
    count_type: str = None         # PLY type name of the list count; None for a scalar

    @property
    def is_list(self):
        return self.count_type is not None

    def header_line(self):
        if self.is_list:
            return f"property list {self.count_type} {self.type} {self.name}"
        return f"property {self.type} {self.name}"


@dataclass
class PlyElement:
    """One element: its name, its row count and its properties, in file order."""

    name: str
    count: int
    properties: list = field(default_factory=list)
    line: int = 0                  # header line of its 'element' statement (1-based; 0 if not from a file)

    def property_names(self):
        return [p.name for p in self.properties]


@dataclass
class PlyHeader:
    """A parsed PLY header.

    Attributes
    ----------
    format : {'ascii', 'binary_little_endian', 'binary_big_endian'}
    elements : list of PlyElement
        In file order (the data follows in this order).
    comments : list of str
        ``comment`` lines (without the keyword), then ``obj_info`` lines prefixed by ``obj_info``.
    n_bytes : int
        Length of the header in bytes, including the newline after ``end_header``.
    n_lines : int
        Number of header lines (the data of an ASCII file starts on line ``n_lines + 1``).
    """

    format: str
    elements: list
    comments: list = field(default_factory=list)
    n_bytes: int = 0
    n_lines: int = 0

    def element(self, name):
        """The element called ``name``, or None."""
        return next((e for e in self.elements if e.name == name), None)

    def text(self):
        """The header as written by :func:`write_ply` (ends with ``end_header\\n``)."""
        lines = ["ply", f"format {self.format} 1.0"]
        for c in self.comments:
            lines.append(c if c.startswith("obj_info") else f"comment {c}".rstrip())
        for e in self.elements:
            lines.append(f"element {e.name} {e.count}")
            lines += [p.header_line() for p in e.properties]
        return "\n".join(lines + ["end_header"]) + "\n"


def _np_type(ply_type, order=""):
    return np.dtype(order + PLY_TYPES[ply_type])


def _header_bytes(data, source):
    """Split ``data`` (bytes) into the header's lines and its length in bytes."""
    if not data.startswith(b"ply"):
        raise ValueError(f"{source}, line 1: a PLY file starts with the line 'ply'; got {data[:20]!r}")
    m = re.search(rb"(^|\n)end_header[ \t]*\r?\n", data)
    if m is None:
        if re.search(rb"(^|\n)end_header[ \t]*\r?$", data):      # header without data (nothing follows)
            n = len(data)
        else:
            raise ValueError(f"{source}: no 'end_header' line: the header is incomplete")
    else:
        n = m.end()
    try:
        text = data[:n].decode("ascii")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise ValueError(f"{source}, line {line}: the header must be ASCII text; byte {data[exc.start]:#04x}") from None
    return text.split("\n")[:-1] if text.endswith("\n") else text.split("\n"), n


def parse_header(data: bytes | str, source: str = "<header>") -> PlyHeader:
    """Check a PLY header against the format's rules and parse it (Turk 1994).

    Parameters
    ----------
    data : bytes or str
        The start of a PLY file: at least the header up to and including ``end_header`` (what follows is ignored).
    source : str
        Name used in error messages (usually the file's path).

    Returns
    -------
    PlyHeader

    Raises
    ------
    ValueError
        ``<source>, line N: ...`` naming the first line that breaks a rule: the first line is not ``ply``; a
        ``format`` other than ``ascii | binary_little_endian | binary_big_endian 1.0``, missing or repeated;
        an unknown keyword; an ``element`` without a name and a non-negative integer count, or a repeated name;
        a ``property`` before any element, with an unknown type, a list count of a non-integer type, a missing
        or repeated name; no ``end_header``.

    Examples
    --------
    >>> h = parse_header("ply\\nformat ascii 1.0\\nelement vertex 2\\nproperty float x\\nend_header\\n")
    >>> h.format, h.elements[0].name, h.elements[0].count, h.elements[0].property_names()
    ('ascii', 'vertex', 2, ['x'])
    >>> bad = "ply\\nformat ascii 1.0\\nelement vertex 2\\nproperty real x\\nend_header\\n"
    >>> parse_header(bad, "a.ply")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: a.ply, line 4: unknown type 'real' (PLY types: char, uchar, short, ushort, int, uint, float, ...
    """
    if isinstance(data, str):
        data = data.encode("ascii", errors="backslashreplace")
    lines, n_bytes = _header_bytes(bytes(data), source)
    types = ", ".join(PLY_TYPES)
    fmt, elements, comments = None, [], []
    for k, raw in enumerate(lines, 1):
        line = raw.rstrip("\r")
        tok = line.split()
        where = f"{source}, line {k}"
        if k == 1:
            if line.strip() != "ply":
                raise ValueError(f"{where}: a PLY file starts with the line 'ply'; got {line!r}")
            continue
        if not tok:
            raise ValueError(f"{where}: empty line in the header")
        key = tok[0]
        if key == "comment":
            comments.append(line.split(None, 1)[1] if len(tok) > 1 else "")
        elif key == "obj_info":
            comments.append(line.strip())
        elif key == "format":
            if fmt is not None:
                raise ValueError(f"{where}: a second 'format' line")
            if elements:
                raise ValueError(f"{where}: 'format' must come before the first element")
            if len(tok) != 3 or tok[1] not in _FORMATS or tok[2] != "1.0":
                raise ValueError(f"{where}: expected 'format ascii 1.0', 'format binary_little_endian 1.0' or "
                                 f"'format binary_big_endian 1.0'; got {line!r}")
            fmt = tok[1]
        elif key == "element":
            if fmt is None:
                raise ValueError(f"{where}: 'element' before the 'format' line (line 2 must be the format)")
            if len(tok) != 3 or not re.fullmatch(r"\d+", tok[2]):
                raise ValueError(f"{where}: expected 'element <name> <count>' with a non-negative integer count; "
                                 f"got {line!r}")
            if any(e.name == tok[1] for e in elements):
                raise ValueError(f"{where}: element '{tok[1]}' is declared twice")
            elements.append(PlyElement(tok[1], int(tok[2]), [], k))
        elif key == "property":
            if not elements:
                raise ValueError(f"{where}: 'property' before any 'element'")
            if len(tok) >= 2 and tok[1] == "list":
                if len(tok) != 5:
                    raise ValueError(f"{where}: expected 'property list <count type> <item type> <name>'; "
                                     f"got {line!r}")
                _, _, ctype, itype, name = tok
                for t in (ctype, itype):
                    if t not in PLY_TYPES:
                        raise ValueError(f"{where}: unknown type '{t}' (PLY types: {types})")
                if PLY_TYPES[ctype][0] == "f":
                    raise ValueError(f"{where}: a list's count must have an integer type; got '{ctype}'")
                prop = PlyProperty(name, itype, ctype)
            else:
                if len(tok) != 3:
                    raise ValueError(f"{where}: expected 'property <type> <name>'; got {line!r}")
                _, ptype, name = tok
                if ptype not in PLY_TYPES:
                    raise ValueError(f"{where}: unknown type '{ptype}' (PLY types: {types})")
                prop = PlyProperty(name, ptype)
            if name in elements[-1].property_names():
                raise ValueError(f"{where}: property '{name}' of element '{elements[-1].name}' is declared twice")
            elements[-1].properties.append(prop)
        elif key == "end_header":
            if len(tok) != 1:
                raise ValueError(f"{where}: 'end_header' takes nothing after it; got {line!r}")
            if fmt is None:
                raise ValueError(f"{where}: the header has no 'format' line")
            return PlyHeader(fmt, elements, comments, n_bytes, k)
        else:
            raise ValueError(f"{where}: unknown keyword '{key}' (a header holds format, comment, obj_info, "
                             "element, property and end_header lines)")
    raise ValueError(f"{source}: no 'end_header' line: the header is incomplete")
