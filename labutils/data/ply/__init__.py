"""PLY files: read, write and validate point clouds and meshes (the Stanford "polygon file format").

The format (Greg Turk, "The PLY polygon file format", 1994; Paul Bourke's page "PLY - Polygon File Format")
is a header of text lines followed by the data::

    ply
    format binary_little_endian 1.0         (or ascii 1.0, binary_big_endian 1.0)
    comment written by labutils.data.ply         (any number of comment / obj_info lines)
    element vertex 8                        (an element: its name and how many rows follow)
    property float x                        (a scalar property: type and name)
    property uchar red
    element face 12
    property list uchar int vertex_indices  (a list: the type of its count, of its items, and its name)
    end_header <8 vertex rows, then 12 face rows: one text line each (ascii), or packed bytes (binary)>

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
from .header import PLY_TYPES, PlyElement, PlyHeader, PlyProperty, parse_header
from .read import PlyModel, read_model, read_ply, validate_ply
from .write import write_mesh, write_ply, write_points

__all__ = ["PLY_TYPES", "PlyProperty", "PlyElement", "PlyHeader", "PlyModel", "parse_header", "validate_ply",
           "read_ply", "write_ply", "read_model", "write_points", "write_mesh"]
