"""Reading PLY files: any elements and properties (ASCII, binary little or big endian), and point clouds or meshes."""
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .header import _FORMATS, PlyHeader, _np_type, parse_header
from .write import _colors


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
                c = int(_to_typed([tok[col]], p.count_type, lambda _, w=where: w + " (list count)")[0])
                if c < 0 or col + 1 + c > len(tok):
                    raise ValueError(f"{where}: the list count {c} needs {c} more values; the row has "
                                     f"{max(len(tok) - col - 1, 0)}")
                cols[p.name].append(_to_typed(tok[col + 1:col + 1 + c], p.type, lambda _, w=where: w))
                col += 1 + c
            else:
                cols[p.name].append(_to_typed([tok[col]], p.type, lambda _, w=where: w)[0])
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


def read_ply(path: str | os.PathLike) -> tuple[PlyHeader, dict[str, dict[str, np.ndarray]]]:
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
    >>> from labutils.data.ply import write_ply
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


def validate_ply(path: str | os.PathLike) -> PlyHeader:
    """Check a PLY file against the format: its header's rules, and data matching the header exactly.

    Returns the :class:`PlyHeader` when the file is valid; raises ``ValueError`` naming the file and the header
    line or element otherwise (see :func:`parse_header` and :func:`read_ply`).

    Examples
    --------
    >>> import tempfile, os
    >>> from labutils.data.ply import write_mesh
    >>> path = os.path.join(tempfile.mkdtemp(), "tri.ply")
    >>> write_mesh(path, np.eye(3), [[0, 1, 2]])
    >>> [(e.name, e.count) for e in validate_ply(path).elements]
    [('vertex', 3), ('face', 1)]
    """
    return read_ply(path)[0]



def read_model(path: str | os.PathLike) -> PlyModel:
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
    >>> from labutils.data.ply import write_mesh
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
