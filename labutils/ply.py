"""PLY files: read, write and validate point clouds and meshes (the Stanford "polygon file format").

The format (Greg Turk, "The PLY polygon file format", 1994; Paul Bourke's page "PLY - Polygon File Format")
is a header of text lines followed by the data::

    ply
    format binary_little_endian 1.0         (or ascii 1.0, binary_big_endian 1.0)
    comment written by labutils.ply         (any number of comment / obj_info lines)
    element vertex 8                        (an element: its name and how many rows follow)
    property float x                        (a scalar property: type and name)
    property uchar red
    element face 12
    property list uchar int vertex_indices  (a list: the type of its count, of its items, and its name)
    end_header
    <8 vertex rows, then 12 face rows: one text line each (ascii), or packed bytes (binary)>

Types: ``char uchar short ushort int uint float double`` and their aliases ``int8 uint8 int16 uint16 int32
uint32 float32 float64``. A list's count must have an integer type.

Layers, from general to specific:

- :func:`parse_header` checks a header against these rules and returns a :class:`PlyHeader`;
  :func:`validate_ply` checks a whole file (header and data);
- :func:`read_ply` / :func:`write_ply`: any elements and properties, as a dict of dicts of arrays;
- :func:`read_model`, :func:`write_points`, :func:`write_mesh`: the workbook's point clouds and meshes
  (``vertex`` with ``x y z``, optional ``nx ny nz`` normals and ``red green blue`` colours; ``face`` with
  ``vertex_indices``), as a :class:`PlyModel`.

Binary files round-trip exactly; ASCII files are written with enough digits (9 for ``float``, 17 for
``double``) that they round-trip exactly as well. Bad input raises ``ValueError`` naming the argument, or the
file and the header line or element where the file is malformed.
"""
import os
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._validation import as_points

__all__ = ["PLY_TYPES", "PlyProperty", "PlyElement", "PlyHeader", "PlyModel", "parse_header", "validate_ply",
           "read_ply", "write_ply", "read_model", "write_points", "write_mesh"]

PLY_TYPES = {
    "char": "i1", "uchar": "u1", "short": "i2", "ushort": "u2", "int": "i4", "uint": "u4", "float": "f4",
    "double": "f8", "int8": "i1", "uint8": "u1", "int16": "i2", "uint16": "u2", "int32": "i4", "uint32": "u4",
    "float32": "f4", "float64": "f8",
}
"""PLY type names (standard and alias) → numpy type codes (without byte order)."""

_NAME_OF = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "u4": "uint",
            "f4": "float", "f8": "double"}
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_NAME_RE = re.compile(r"^[^\s]+$")


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


@dataclass
class PlyModel:
    """A point cloud or a mesh, as the workbook writes it.

    Attributes
    ----------
    vertices : (N, 3) float ndarray
    faces : (F, k) int ndarray or None
        Vertex indices of each face (all faces with k corners); None for a point cloud.
    colors : (N, 3) uint8 ndarray or None
        Per-vertex ``red green blue``.
    normals : (N, 3) float ndarray or None
        Per-vertex ``nx ny nz``.
    comments : list of str
    """

    vertices: np.ndarray
    faces: np.ndarray = None
    colors: np.ndarray = None
    normals: np.ndarray = None
    comments: list = field(default_factory=list)


# ---------------------------------------------------------------------------------------------------------------
# The header
# ---------------------------------------------------------------------------------------------------------------
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


def parse_header(data, source="<header>"):
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


# ---------------------------------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------------------------------
def _np_type(ply_type, order=""):
    return np.dtype(order + PLY_TYPES[ply_type])


def _read_ascii(header, body, source):
    lines = body.split("\n")
    pos, out = 0, {}
    for e in header.elements:
        rows = []
        while len(rows) < e.count:
            if pos >= len(lines):
                raise ValueError(f"{source}: element '{e.name}' declares {e.count} rows; the file ends after "
                                 f"{len(rows)}")
            tok = lines[pos].split()
            pos += 1
            if tok:                                   # blank lines between rows are tolerated
                rows.append((header.n_lines + pos, tok))
        out[e.name] = _parse_ascii_rows(e, rows, source)
    rest = [k for k in range(pos, len(lines)) if lines[k].strip()]
    if rest:
        raise ValueError(f"{source}, line {header.n_lines + rest[0] + 1}: data after the last element "
                         f"('{header.elements[-1].name}' if any declares fewer rows than the file holds)")
    return out


def _to_typed(values, ply_type, where):
    """Strings → numbers of a PLY type, checking that integers are integers and in range.

    ``where(k)`` names row k of ``values`` in an error message.
    """
    dt = _np_type(ply_type)
    values = np.asarray(values)
    try:
        if dt.kind == "f":
            return values.astype(float).astype(dt)
        a = values.astype(np.int64)
    except (ValueError, OverflowError):
        flat = values.reshape(len(values), -1) if values.ndim else values.reshape(1, 1)
        k, j = next((k, j) for k in range(len(flat)) for j in range(flat.shape[1])
                    if not _is_number(flat[k, j], dt.kind))
        raise ValueError(f"{where(k)}: {str(flat[k, j])!r} is not a valid {ply_type}") from None
    info = np.iinfo(dt)
    bad = (a < info.min) | (a > info.max)
    if bad.any():
        k = int(np.flatnonzero(bad.reshape(len(a), -1).any(axis=1))[0]) if a.ndim else 0
        v = a.reshape(len(a), -1)[k][bad.reshape(len(a), -1)[k]][0] if a.ndim else a
        raise ValueError(f"{where(k)}: {v} is out of range for {ply_type} ({info.min}..{info.max})")
    return a.astype(dt)


def _is_number(s, kind):
    try:
        float(s) if kind == "f" else int(s)
        return True
    except ValueError:
        return False


def _parse_ascii_rows(e, rows, source):
    def at(name, suffix=""):
        return lambda k: f"{source}, line {rows[k][0]}: element '{e.name}' row {k}, property '{name}'{suffix}"

    if not rows:
        return {p.name: (np.zeros((0, 0), _np_type(p.type)) if p.is_list else np.zeros(0, _np_type(p.type)))
                for p in e.properties}
    lens = np.array([len(t) for _, t in rows])
    if not any(p.is_list for p in e.properties):
        n = len(e.properties)
        if np.any(lens != n):
            k = int(np.flatnonzero(lens != n)[0])
            raise ValueError(f"{source}, line {rows[k][0]}: element '{e.name}' row {k} has {lens[k]} values; "
                             f"expected {n} ({' '.join(e.property_names())})")
        table = np.array([t for _, t in rows])
        return {p.name: _to_typed(table[:, j], p.type, at(p.name)) for j, p in enumerate(e.properties)}
    # with lists: fast path when every row has the same length and layout, else row by row
    if np.all(lens == lens[0]):
        table = np.array([t for _, t in rows])
        out, col, ok = {}, 0, True
        for p in e.properties:
            if p.is_list:
                counts = _to_typed(table[:, col], p.count_type, at(p.name, " (list count)"))
                if np.any(counts != counts[0]) or col + 1 + int(counts[0]) > table.shape[1]:
                    ok = False
                    break
                c = int(counts[0])
                out[p.name] = _to_typed(table[:, col + 1:col + 1 + c], p.type, at(p.name))
                col += 1 + c
            else:
                out[p.name] = _to_typed(table[:, col], p.type, at(p.name))
                col += 1
        if ok and col == table.shape[1]:
            return out
    cols = {p.name: [] for p in e.properties}
    for k, (lineno, tok) in enumerate(rows):
        col = 0
        for p in e.properties:
            where = f"{source}, line {lineno}: element '{e.name}' row {k}, property '{p.name}'"
            if col >= len(tok):
                raise ValueError(f"{where}: the row ends early ({len(tok)} values)")
            if p.is_list:
                c = int(_to_typed([tok[col]], p.count_type, lambda _: where + " (list count)")[0])
                if c < 0 or col + 1 + c > len(tok):
                    raise ValueError(f"{where}: the list count {c} needs {c} more values; the row has "
                                     f"{max(len(tok) - col - 1, 0)}")
                cols[p.name].append(_to_typed(tok[col + 1:col + 1 + c], p.type, lambda _: where))
                col += 1 + c
            else:
                cols[p.name].append(_to_typed([tok[col]], p.type, lambda _: where)[0])
                col += 1
        if col != len(tok):
            raise ValueError(f"{source}, line {lineno}: element '{e.name}' row {k} has {len(tok) - col} values "
                             "more than its properties")
    return {p.name: _lists_to_array(cols[p.name], p.type) if p.is_list else np.array(cols[p.name],
                                                                                        _np_type(p.type))
            for p in e.properties}


def _lists_to_array(lists, ply_type):
    """A (N, k) array when all lists have length k, else an object array of 1-D arrays."""
    if lists and all(len(a) == len(lists[0]) for a in lists):
        return np.array(lists, dtype=_np_type(ply_type)).reshape(len(lists), len(lists[0]))
    out = np.empty(len(lists), dtype=object)
    out[:] = [np.asarray(a, _np_type(ply_type)) for a in lists]
    return out


def _read_binary(header, body, source):
    order = _FORMATS[header.format]
    pos, out = 0, {}
    for e in header.elements:
        out[e.name], pos = _read_binary_element(e, body, pos, order, source)
    if pos != len(body):
        raise ValueError(f"{source}: {len(body) - pos} bytes after the last element "
                         f"('{header.elements[-1].name}' if any declares fewer rows than the file holds)")
    return out


def _read_binary_element(e, body, pos, order, source):
    what = f"{source}: element '{e.name}'"

    def short(n_needed):
        return ValueError(f"{what} needs {n_needed} bytes from byte {pos}; the file ends after {len(body) - pos}")

    if e.count == 0:
        return {p.name: (np.zeros((0, 0), _np_type(p.type)) if p.is_list else np.zeros(0, _np_type(p.type)))
                for p in e.properties}, pos
    # guess a fixed layout from the first row (all lists as long as the first row's), check it, else row by row
    fields, p0 = [], pos
    for p in e.properties:
        if p.is_list:
            ct = _np_type(p.count_type, order)
            if p0 + ct.itemsize > len(body):
                raise short(p0 + ct.itemsize - pos)
            c = int(np.frombuffer(body, ct, 1, p0)[0])
            if c < 0:
                raise ValueError(f"{what}, property '{p.name}': negative list count {c} in row 0")
            fields += [(f"{p.name}#count", ct), (p.name, _np_type(p.type, order), (c,))]
            p0 += ct.itemsize + c * _np_type(p.type).itemsize
        else:
            fields.append((p.name, _np_type(p.type, order)))
            p0 += _np_type(p.type).itemsize
    dt = np.dtype(fields)
    fixed = dt.itemsize * e.count <= len(body) - pos
    if fixed:
        rec = np.frombuffer(body, dt, e.count, pos)
        fixed = all(np.all(rec[f"{p.name}#count"] == dt[p.name].shape[0]) for p in e.properties if p.is_list)
    if fixed:
        out = {}
        for p in e.properties:
            a = np.array(rec[p.name]).astype(_np_type(p.type))
            out[p.name] = a.reshape(e.count, -1) if p.is_list else a
        return out, pos + dt.itemsize * e.count
    if not any(p.is_list for p in e.properties):
        raise short(dt.itemsize * e.count)
    cols = {p.name: [] for p in e.properties}
    for k in range(e.count):
        for p in e.properties:
            if p.is_list:
                ct = _np_type(p.count_type, order)
                if pos + ct.itemsize > len(body):
                    raise ValueError(f"{what}, row {k} of {e.count}: the file ends in the list count of '{p.name}'")
                c = int(np.frombuffer(body, ct, 1, pos)[0])
                pos += ct.itemsize
                it = _np_type(p.type, order)
                if c < 0 or pos + c * it.itemsize > len(body):
                    raise ValueError(f"{what}, row {k} of {e.count}: the list '{p.name}' of {c} items runs past the "
                                     "end of the file")
                cols[p.name].append(np.frombuffer(body, it, c, pos).astype(_np_type(p.type)))
                pos += c * it.itemsize
            else:
                it = _np_type(p.type, order)
                if pos + it.itemsize > len(body):
                    raise ValueError(f"{what}, row {k} of {e.count}: the file ends in property '{p.name}'")
                cols[p.name].append(np.frombuffer(body, it, 1, pos)[0])
                pos += it.itemsize
    return {p.name: _lists_to_array(cols[p.name], p.type) if p.is_list else np.array(cols[p.name],
                                                                                        _np_type(p.type))
            for p in e.properties}, pos


def read_ply(path):
    """Read any PLY file: its header and, per element, one array per property.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    header : PlyHeader
    data : dict
        ``data[element][property]`` is an ``(count,)`` array of the property's type (native byte order); a list
        property is a ``(count, k)`` array when every row's list has k items, else an object array of 1-D arrays.

    Raises
    ------
    ValueError
        A malformed header (file and line named), or data that does not match it (file and element named; for
        ASCII files also the line): too few or too many rows or bytes, a value that is not a number of its
        type or is out of its type's range, a list whose count runs past its row.
    FileNotFoundError
        If ``path`` does not exist.

    Examples
    --------
    >>> import tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "two.ply")
    >>> write_ply(path, {"vertex": {"x": np.array([1.5, 2.0], np.float32)}}, format="ascii")
    >>> header, data = read_ply(path)
    >>> header.format, data["vertex"]["x"]
    ('ascii', array([1.5, 2. ], dtype=float32))
    """
    source = str(path)
    raw = Path(path).read_bytes()
    header = parse_header(raw, source)
    body = raw[header.n_bytes:]
    if header.format == "ascii":
        try:
            text = body.decode("ascii")
        except UnicodeDecodeError as exc:
            line = header.n_lines + body[:exc.start].count(b"\n") + 1
            raise ValueError(f"{source}, line {line}: non-ASCII byte {body[exc.start]:#04x} in an ASCII PLY file") \
                from None
        return header, _read_ascii(header, text, source)
    return header, _read_binary(header, body, source)


def validate_ply(path):
    """Check a PLY file against the format: its header's rules, and data matching the header exactly.

    Returns the :class:`PlyHeader` when the file is valid; raises ``ValueError`` naming the file and the header
    line or element otherwise (see :func:`parse_header` and :func:`read_ply`).

    Examples
    --------
    >>> import tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "tri.ply")
    >>> write_mesh(path, np.eye(3), [[0, 1, 2]])
    >>> [(e.name, e.count) for e in validate_ply(path).elements]
    [('vertex', 3), ('face', 1)]
    """
    return read_ply(path)[0]


# ---------------------------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------------------------
def _ply_type_of(a, name):
    """The PLY type a numpy array is written as by default (64-bit integers: int/uint when the values fit)."""
    a = np.asarray(a)
    code = a.dtype.str[1:]
    if code == "b1":
        return "uchar"
    if code in ("i8", "u8"):
        lo, hi = (int(a.min()), int(a.max())) if a.size else (0, 0)
        if code == "i8" and -2 ** 31 <= lo and hi < 2 ** 31:
            return "int"
        if lo >= 0 and hi < 2 ** 32:
            return "uint"
        raise ValueError(f"{name} holds 64-bit integers outside the 32-bit range ({lo}..{hi}); PLY has no 64-bit "
                         "integer type")
    if code not in _NAME_OF:
        raise ValueError(f"{name} has dtype {a.dtype}, which has no PLY type (PLY types: "
                         f"{', '.join(_NAME_OF.values())})")
    return _NAME_OF[code]


def _as_column(values, ply_type, name, n, is_list):
    """Check and convert one property's values to its numpy type; ``name`` is used in errors."""
    a = values
    if is_list and isinstance(values, (list, tuple)) and values and np.ndim(values[0]) == 1 \
            and len({len(v) for v in values}) > 1:
        a = np.empty(len(values), dtype=object)
        a[:] = [np.asarray(v) for v in values]
    else:
        a = np.asarray(values)
    if a.dtype == object and is_list:
        if a.ndim != 1 or len(a) != n:
            raise ValueError(f"{name} must hold {n} lists; got {a.shape}")
        items = [_as_column(v, ply_type, f"{name}[{i}]", len(np.ravel(v)), False) for i, v in enumerate(a)]
        return items
    want = 2 if is_list else 1
    if a.ndim != want or a.shape[0] != n:
        raise ValueError(f"{name} must have shape ({n},{' k' if is_list else ''}) to match the element's {n} rows; "
                         f"got shape {a.shape}")
    dt = _np_type(ply_type)
    if a.dtype.kind not in "biuf":
        raise ValueError(f"{name} must be numeric; got dtype {a.dtype}")
    if dt.kind == "f":
        if not np.all(np.isfinite(a)):
            bad = np.flatnonzero(~np.isfinite(a).reshape(len(a), -1).all(axis=1))
            raise ValueError(f"{name} has non-finite values (NaN or inf) in rows {bad[:5].tolist()}")
        return a.astype(dt)
    if a.dtype.kind == "f" and not np.all(np.isfinite(a) & (a == np.round(a))):
        raise ValueError(f"{name} must hold integers for PLY type {ply_type}; got non-integer values")
    info = np.iinfo(dt)
    if a.size and (a.min() < info.min or a.max() > info.max):
        raise ValueError(f"{name} must lie in {info.min}..{info.max} for PLY type {ply_type}; got values in "
                         f"{a.min()}..{a.max()}")
    return a.astype(dt)


def _fmt(ply_type):
    """printf format of a PLY type in ASCII: enough digits to round-trip exactly (9 for float, 17 for double)."""
    return {"f4": "%.9g", "f8": "%.17g"}.get(PLY_TYPES[ply_type], "%d")


def _write_atomic(path, chunks):
    """Write ``chunks`` (bytes) to a temporary file beside ``path`` and rename it; remove it on any failure."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise ValueError(f"{path}: the folder {folder} does not exist")
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            for c in chunks:
                f.write(c)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def write_ply(path, elements, *, format="binary_little_endian", comments=(), types=None):
    """Write any elements and properties as a PLY file (atomically: a temporary file renamed into place).

    Parameters
    ----------
    path : str or Path
    elements : dict
        ``{element name: {property name: values}}`` in file order. Scalar values are ``(count,)`` arrays; a list
        property is a ``(count, k)`` integer/float array or a sequence of 1-D arrays (lists of varying length).
    format : {'binary_little_endian', 'ascii', 'binary_big_endian'}
    comments : sequence of str
        Written as ``comment`` lines (one line each, no newlines).
    types : dict, optional
        ``{(element, property): ply type}`` (for a list, ``'<count type> <item type>'``, e.g. ``'uchar int'``);
        by default the type follows each array's dtype (float32 → float, float64 → double, uint8 → uchar,
        int32 → int, ...; a list's count is ``uchar``, or ``int`` for lists longer than 255).

    Raises
    ------
    ValueError
        Naming the element and property: wrong shapes, row counts that differ within an element, non-finite
        floats, integers out of their type's range; an unknown format or type; a folder that does not exist.

    Examples
    --------
    >>> import tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "v.ply")
    >>> write_ply(path, {"vertex": {"x": np.zeros(2, np.float32), "y": np.ones(2, np.float32)}}, format="ascii")
    >>> print(open(path).read(), end="")
    ply
    format ascii 1.0
    element vertex 2
    property float x
    property float y
    end_header
    0 1
    0 1
    """
    if format not in _FORMATS:
        raise ValueError(f"format must be one of {list(_FORMATS)}; got {format!r}")
    types = dict(types or {})
    for c in comments:
        if "\n" in c or "\r" in c:
            raise ValueError(f"comments must be single lines; got {c!r}")
    header_elems, columns = [], []
    for ename, props in elements.items():
        if not _NAME_RE.match(str(ename)):
            raise ValueError(f"element name {ename!r} must be one word")
        if not props:
            raise ValueError(f"element '{ename}' has no properties")
        n = None
        e = PlyElement(str(ename), 0, [])
        cols = []
        for pname, values in props.items():
            if not _NAME_RE.match(str(pname)):
                raise ValueError(f"property name {pname!r} of element '{ename}' must be one word")
            name = f"element '{ename}', property '{pname}'"
            arr = values if isinstance(values, np.ndarray) else None
            is_list = (arr is not None and (arr.ndim == 2 or arr.dtype == object)) or \
                (arr is None and isinstance(values, (list, tuple)) and len(values) > 0 and np.ndim(values[0]) >= 1)
            rows = len(values)
            if n is None:
                n = rows
            elif rows != n:
                raise ValueError(f"{name} has {rows} rows; the element's other properties have {n}")
            spec = types.get((ename, pname))
            if is_list:
                if spec is None:
                    probe = values if arr is not None and arr.dtype != object else (
                        np.concatenate([np.ravel(v) for v in values]) if rows else np.zeros(0, "i4"))
                    maxlen = max((len(np.ravel(v)) for v in values), default=0)
                    spec = f"{'uchar' if maxlen <= 255 else 'int'} {_ply_type_of(probe, name)}"
                parts = spec.split()
                if len(parts) != 2 or any(t not in PLY_TYPES for t in parts) or PLY_TYPES[parts[0]][0] == "f":
                    raise ValueError(f"{name}: a list type is '<integer count type> <item type>'; got {spec!r}")
                prop = PlyProperty(str(pname), parts[1], parts[0])
                col = _as_column(values, prop.type, name, n, True)
                counts = [len(v) for v in col] if isinstance(col, list) else [col.shape[1]] * n
                _as_column(np.array(counts), prop.count_type, f"{name} (list lengths)", n, False)
            else:
                if spec is None:
                    spec = _ply_type_of(np.asarray(values), name)
                if spec not in PLY_TYPES:
                    raise ValueError(f"{name}: unknown PLY type {spec!r}")
                prop = PlyProperty(str(pname), spec)
                col = _as_column(values, spec, name, n, False)
            e.properties.append(prop)
            cols.append(col)
        e.count = int(n)
        header_elems.append(e)
        columns.append(cols)
    header = PlyHeader(format, header_elems, list(comments))
    _write_atomic(path, _encode(header, columns))


def _encode(header, columns):
    yield header.text().encode("ascii")
    order = _FORMATS[header.format]
    for e, cols in zip(header.elements, columns):
        if e.count == 0:
            continue
        ragged = any(isinstance(c, list) for c in cols)
        if header.format == "ascii":
            yield _ascii_rows(e, cols, ragged).encode("ascii")
        elif not ragged:
            fields = []
            for p, c in zip(e.properties, cols):
                if p.is_list:
                    fields += [(f"{p.name}#count", order + PLY_TYPES[p.count_type]),
                               (p.name, order + PLY_TYPES[p.type], (c.shape[1],))]
                else:
                    fields.append((p.name, order + PLY_TYPES[p.type]))
            rec = np.empty(e.count, dtype=fields)
            for p, c in zip(e.properties, cols):
                if p.is_list:
                    rec[f"{p.name}#count"] = c.shape[1]
                rec[p.name] = c
            yield rec.tobytes()
        else:
            parts = []
            for k in range(e.count):
                for p, c in zip(e.properties, cols):
                    if p.is_list:
                        v = c[k] if isinstance(c, list) else c[k]
                        parts.append(np.array(len(v), order + PLY_TYPES[p.count_type]).tobytes())
                        parts.append(np.asarray(v).astype(order + PLY_TYPES[p.type]).tobytes())
                    else:
                        parts.append(np.array(c[k], order + PLY_TYPES[p.type]).tobytes())
            yield b"".join(parts)


def _ascii_rows(e, cols, ragged):
    if not ragged:
        fmts, blocks = [], []
        for p, c in zip(e.properties, cols):
            f = _fmt(p.type)
            if p.is_list:
                fmts += ["%d"] + [f] * c.shape[1]
                blocks += [np.full((e.count, 1), c.shape[1], dtype=object), c.astype(object)]
            else:
                fmts.append(f)
                blocks.append(c.astype(object)[:, None])
        table = np.hstack(blocks)
        row = " ".join(fmts)
        return "".join(row % tuple(_py(r)) + "\n" for r in table)
    lines = []
    for k in range(e.count):
        vals = []
        for p, c in zip(e.properties, cols):
            f = _fmt(p.type)
            if p.is_list:
                v = c[k]
                vals.append(str(len(v)))
                vals += [f % x for x in _py(v)]
            else:
                vals.append(f % _py([c[k]])[0])
        lines.append(" ".join(vals) + "\n")
    return "".join(lines)


def _py(values):
    """numpy scalars → Python numbers (float32 goes through float, which keeps its exact value)."""
    return [float(v) if isinstance(v, (np.floating, float)) else int(v) for v in values]


# ---------------------------------------------------------------------------------------------------------------
# Point clouds and meshes
# ---------------------------------------------------------------------------------------------------------------
def _colors(colors, n, name="colors"):
    if colors is None:
        return None
    c = np.asarray(colors)
    if c.ndim != 2 or c.shape != (n, 3):
        raise ValueError(f"{name} must have shape ({n}, 3) (red green blue per vertex); got shape {c.shape}")
    if c.dtype.kind not in "biuf":
        raise ValueError(f"{name} must be numeric (uchar 0..255); got dtype {c.dtype}")
    if c.dtype.kind == "f":
        if not np.all(np.isfinite(c)):
            raise ValueError(f"{name} has non-finite values (NaN or inf)")
        if np.any(c != np.round(c)):
            hint = " (they look like 0..1 colours: multiply by 255 and round)" if c.size and c.max() <= 1 else ""
            raise ValueError(f"{name} must be integers 0..255 (uchar); got non-integer values{hint}")
    if c.size and (c.min() < 0 or c.max() > 255):
        raise ValueError(f"{name} must lie in 0..255 (uchar); got values in {c.min()}..{c.max()}")
    return c.astype(np.uint8)


def _vertex_props(X, colors, normals, coord_type, name):
    if coord_type not in ("float", "double"):
        raise ValueError(f"coord_type must be 'float' or 'double'; got {coord_type!r}")
    X = as_points(X, name, dim=3, min_n=0)
    dt = np.float32 if coord_type == "float" else np.float64
    props = {"x": X[:, 0].astype(dt), "y": X[:, 1].astype(dt), "z": X[:, 2].astype(dt)}
    if normals is not None:
        N = as_points(normals, "normals", dim=3, min_n=0, like=X)
        props.update(nx=N[:, 0].astype(np.float32), ny=N[:, 1].astype(np.float32), nz=N[:, 2].astype(np.float32))
    c = _colors(colors, len(X))
    if c is not None:
        props.update(red=c[:, 0], green=c[:, 1], blue=c[:, 2])
    return X, props


def write_points(path, X, colors=None, normals=None, *, format="binary_little_endian", coord_type="float",
                 comments=()):
    """Write a point cloud: ``x y z``, optional ``nx ny nz`` (float) and ``red green blue`` (uchar) per vertex.

    Parameters
    ----------
    path : str or Path
    X : (N, 3) array_like
        Points, finite.
    colors : (N, 3) array_like of integers 0..255, optional
    normals : (N, 3) array_like, optional
    format : {'binary_little_endian', 'ascii', 'binary_big_endian'}
    coord_type : {'float', 'double'}
        Type of ``x y z``: ``float`` (32-bit, what most viewers expect) or ``double`` (exact for float64 input).
    comments : sequence of str

    Raises
    ------
    ValueError
        Naming the argument: a shape other than (N, 3), NaN or inf, colours that are not integers in 0..255.

    Examples
    --------
    >>> import tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "pts.ply")
    >>> write_points(path, [[0, 0, 1], [1, 2, 3]], colors=[[255, 0, 0], [0, 255, 0]], format="ascii")
    >>> print(open(path).read().split("end_header\\n")[1], end="")
    0 0 1 255 0 0
    1 2 3 0 255 0
    >>> write_points(path, [[0, 0, np.nan]])
    Traceback (most recent call last):
    ...
    ValueError: X has non-finite coordinates (NaN or inf) in rows [0]
    """
    _, props = _vertex_props(X, colors, normals, coord_type, "X")
    write_ply(path, {"vertex": props}, format=format, comments=comments)


def write_mesh(path, vertices, faces, colors=None, normals=None, *, format="binary_little_endian",
               coord_type="float", comments=()):
    """Write a mesh: vertices (with optional per-vertex colours and normals) and faces as vertex-index lists.

    Faces are written as ``property list uchar int vertex_indices``.

    Parameters
    ----------
    path : str or Path
    vertices : (N, 3) array_like
    faces : (F, k) array_like of int
        Vertex indices, ``0 <= index < N``, k >= 3 (triangles: k = 3).
    colors, normals, format, coord_type, comments
        As in :func:`write_points`.

    Raises
    ------
    ValueError
        Naming the argument: wrong shapes, NaN vertices, face indices out of range, faces with fewer than 3
        corners, colours out of 0..255.

    Examples
    --------
    >>> import tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "tri.ply")
    >>> write_mesh(path, np.eye(3), [[0, 1, 3]])
    Traceback (most recent call last):
    ...
    ValueError: faces hold vertex indices 0..2 (3 vertices); got index 3 in face 0
    """
    X, props = _vertex_props(vertices, colors, normals, coord_type, "vertices")
    F = np.asarray(faces)
    if F.dtype.kind not in "iuf" or F.ndim != 2 or (F.size and F.shape[1] < 3):
        raise ValueError(f"faces must be an integer array of shape (F, k), k >= 3 corners per face; got shape "
                         f"{F.shape} and dtype {F.dtype}")
    if F.dtype.kind == "f":
        if not np.all(np.isfinite(F)) or np.any(F != np.round(F)):
            raise ValueError("faces must hold integer vertex indices; got non-integer values")
    if F.size and (F.min() < 0 or F.max() >= len(X)):
        bad = int(np.flatnonzero(np.any((F < 0) | (F >= len(X)), axis=1))[0])
        v = F[bad][(F[bad] < 0) | (F[bad] >= len(X))][0]
        raise ValueError(f"faces hold vertex indices 0..{len(X) - 1} ({len(X)} vertices); got index {int(v)} in "
                         f"face {bad}")
    if F.shape[1:] and F.shape[1] > 255:
        raise ValueError(f"faces have {F.shape[1]} corners; the 'uchar' count allows at most 255")
    F = F.astype(np.int32).reshape(len(F), -1 if F.size else 3)
    write_ply(path, {"vertex": props, "face": {"vertex_indices": F}}, format=format, comments=comments,
              types={("face", "vertex_indices"): "uchar int"})


def read_model(path):
    """Read a point cloud or a mesh written by :func:`write_points` / :func:`write_mesh` (or any similar PLY).

    Needs an element ``vertex`` with ``x y z``; reads ``nx ny nz`` and ``red green blue`` when all three are
    present, and the faces from ``face`` / ``vertex_indices`` (or ``vertex_index``).

    Returns
    -------
    PlyModel
        ``vertices`` as float64 (the file's float values exactly); ``faces`` as an (F, k) int64 array when every
        face has k corners (ragged faces: an object array), or None without a face element.

    Raises
    ------
    ValueError
        Naming the file: no ``vertex`` element or no ``x y z``, non-finite coordinates, face indices out of range,
        and anything :func:`read_ply` rejects.

    Examples
    --------
    >>> import tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "m.ply")
    >>> write_mesh(path, np.eye(3), [[0, 1, 2]], colors=[[1, 2, 3]] * 3)
    >>> m = read_model(path)
    >>> m.vertices.shape, m.faces.tolist(), m.colors[0].tolist(), m.normals
    ((3, 3), [[0, 1, 2]], [1, 2, 3], None)
    """
    header, data = read_ply(path)
    if "vertex" not in data:
        raise ValueError(f"{path}: no 'vertex' element (elements: {[e.name for e in header.elements]})")
    v = data["vertex"]
    if not all(k in v for k in "xyz"):
        raise ValueError(f"{path}: element 'vertex' lacks x, y or z (properties: {list(v)})")
    X = np.stack([v[k].astype(float) for k in "xyz"], axis=1)
    if not np.all(np.isfinite(X)):
        raise ValueError(f"{path}: element 'vertex' has non-finite coordinates (NaN or inf) in rows "
                         f"{np.flatnonzero(~np.isfinite(X).all(1))[:5].tolist()}")
    normals = np.stack([v[k].astype(float) for k in ("nx", "ny", "nz")], 1) if all(
        k in v for k in ("nx", "ny", "nz")) else None
    colors = None
    if all(k in v for k in ("red", "green", "blue")):
        c = np.stack([v[k] for k in ("red", "green", "blue")], 1)
        colors = c.astype(np.uint8) if c.dtype == np.uint8 else _colors(c, len(X), f"{path}: vertex colours")
    faces = None
    if "face" in data:
        f = data["face"]
        key = "vertex_indices" if "vertex_indices" in f else "vertex_index" if "vertex_index" in f else None
        if key is None:
            raise ValueError(f"{path}: element 'face' has no 'vertex_indices' list (properties: {list(f)})")
        faces = f[key]
        flat = np.concatenate([np.ravel(a) for a in faces]) if faces.dtype == object else faces.ravel()
        if flat.size and (flat.min() < 0 or flat.max() >= len(X)):
            bad = int(flat.min() if flat.min() < 0 else flat.max())
            raise ValueError(f"{path}: element 'face' has vertex index {bad}; the file has {len(X)} vertices")
        if faces.dtype != object:
            faces = faces.astype(np.int64).reshape(len(faces), -1)
    return PlyModel(X, faces, colors, normals, list(header.comments))
