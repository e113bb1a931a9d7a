"""Writing PLY files: any elements and properties, and the workbook's point clouds and meshes, atomically."""
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ...core.cli import write_atomically
from ...core.validation import as_points
from .header import _FORMATS, _NAME_OF, PLY_TYPES, PlyElement, PlyHeader, PlyProperty, _np_type

_NAME_RE = re.compile(r"^[^\s]+$")


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
    write_atomically(path, b"".join(chunks))


def write_ply(path: str | os.PathLike, elements: Mapping[str, Mapping[str, ArrayLike]], *,
              format: str = "binary_little_endian", comments: Sequence[str] = (),
              types: Mapping[tuple[str, str], str] | None = None) -> None:
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


def write_points(path: str | os.PathLike, X: ArrayLike, colors: ArrayLike | None = None,
                 normals: ArrayLike | None = None, *, format: str = "binary_little_endian", coord_type: str = "float",
                 comments: Sequence[str] = ()) -> None:
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


def write_mesh(path: str | os.PathLike, vertices: ArrayLike, faces: ArrayLike, colors: ArrayLike | None = None,
               normals: ArrayLike | None = None, *, format: str = "binary_little_endian", coord_type: str = "float",
               comments: Sequence[str] = ()) -> None:
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
