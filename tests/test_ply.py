"""PLY files: header rules, round trips (binary exact, ASCII to its printed precision), bad input, malformed files."""
import os
import stat

import numpy as np
import pytest

from labutils.data.formats import ply_text
from labutils.data.ply import (
    PLY_TYPES,
    parse_header,
    read_model,
    read_ply,
    validate_ply,
    write_mesh,
    write_ply,
    write_points,
)

# Greg Turk's example from "The PLY polygon file format" (1994): a cube, with a comment and an obj_info line.
TURK_CUBE = """ply
format ascii 1.0
comment made by Greg Turk
comment this file is a cube
element vertex 8
property float x
property float y
property float z
element face 6
property list uchar int vertex_index
end_header
0 0 0
0 0 1
0 1 1
0 1 0
1 0 0
1 0 1
1 1 1
1 1 0
4 0 1 2 3
4 7 6 5 4
4 0 4 5 1
4 1 5 6 2
4 2 6 7 3
4 3 7 4 0
"""

# Paul Bourke's page: a file with per-face colours and an edge element (two lists in different elements).
BOURKE_EDGES = """ply
format ascii 1.0
comment author: Paul Bourke
obj_info a cube with coloured vertices
element vertex 8
property float x
property float y
property float z
property uchar red
property uchar green
property uchar blue
element face 7
property list uchar int vertex_index
element edge 5
property int vertex1
property int vertex2
property uchar red
property uchar green
property uchar blue
end_header
0 0 0 255 0 0
0 0 1 255 0 0
0 1 1 255 0 0
0 1 0 255 0 0
1 0 0 0 0 255
1 0 1 0 0 255
1 1 1 0 0 255
1 1 0 0 0 255
3 0 1 2
3 0 2 3
4 7 6 5 4
4 0 4 5 1
4 1 5 6 2
4 2 6 7 3
4 3 7 4 0
0 1 255 255 255
1 2 255 255 255
2 3 255 255 255
3 0 255 255 255
2 0 0 0 0
"""


def cloud(rng, n=50):
    X = rng.normal(size=(n, 3)) * [1.0, 10.0, 1e-3]
    N = rng.normal(size=(n, 3))
    return X, rng.integers(0, 256, size=(n, 3)), N / np.linalg.norm(N, axis=1, keepdims=True)


def write(tmp_path, text, name="f.ply"):
    p = tmp_path / name
    p.write_bytes(text.encode() if isinstance(text, str) else text)
    return p


# --- the header ------------------------------------------------------------------------------------------------


def test_header_all_types_and_aliases():
    lines = ["ply", "format binary_little_endian 1.0", "comment hello world", "obj_info scanned 1994",
             "element vertex 3"] + [f"property {t} p_{t}" for t in PLY_TYPES] + \
        ["element face 0", "property list uint8 int32 vertex_indices", "end_header", ""]
    h = parse_header("\n".join(lines))
    assert h.format == "binary_little_endian" and h.n_lines == len(lines) - 1
    assert [p.type for p in h.elements[0].properties] == list(PLY_TYPES)
    assert h.elements[1].properties[0].is_list and h.elements[1].properties[0].count_type == "uint8"
    assert h.comments == ["hello world", "obj_info scanned 1994"]
    assert h.n_bytes == len("\n".join(lines).encode())


@pytest.mark.parametrize("text, message", [
    ("plx\nformat ascii 1.0\nend_header\n", "line 1: a PLY file starts with the line 'ply'"),
    ("ply\nformat ascii 2.0\nend_header\n", "line 2: expected 'format ascii 1.0'"),
    ("ply\nformat binary 1.0\nend_header\n", "line 2: expected 'format ascii 1.0'"),
    ("ply\nformat ascii 1.0\nformat ascii 1.0\nend_header\n", "line 3: a second 'format' line"),
    ("ply\nelement vertex 1\nend_header\n", "line 2: 'element' before the 'format' line"),
    ("ply\nformat ascii 1.0\nproperty float x\nend_header\n", "line 3: 'property' before any 'element'"),
    ("ply\nformat ascii 1.0\nelement vertex -1\nend_header\n", "line 3: expected 'element <name> <count>'"),
    ("ply\nformat ascii 1.0\nelement vertex 2.5\nend_header\n", "line 3: expected 'element <name> <count>'"),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty real x\nend_header\n", "line 4: unknown type 'real'"),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float\nend_header\n", "line 4: expected 'property <type>"),
    ("ply\nformat ascii 1.0\nelement f 1\nproperty list float int v\nend_header\n",
     "line 4: a list's count must have an integer type; got 'float'"),
    ("ply\nformat ascii 1.0\nelement f 1\nproperty list uchar int\nend_header\n", "line 4: expected 'property list"),
    ("ply\nformat ascii 1.0\nelement v 1\nelement v 1\nend_header\n", "line 4: element 'v' is declared twice"),
    ("ply\nformat ascii 1.0\nelement v 1\nproperty float x\nproperty int x\nend_header\n",
     "line 5: property 'x' of element 'v' is declared twice"),
    ("ply\nformat ascii 1.0\nelement v 1\nvertex float x\nend_header\n", "line 4: unknown keyword 'vertex'"),
    ("ply\nformat ascii 1.0\n\nend_header\n", "line 3: empty line in the header"),
    ("ply\nformat ascii 1.0\nelement v 1\nproperty float x\n", "no 'end_header' line"),
    ("ply\ncomment no format\nend_header\n", "line 3: the header has no 'format' line"),
])
def test_header_rules(text, message):
    with pytest.raises(ValueError, match=r"^hdr\.ply.*" + message.replace("(", r"\(").replace("'", "'")):
        parse_header(text, "hdr.ply")


def test_header_accepts_crlf_and_ignores_the_data():
    h = parse_header(b"ply\r\nformat ascii 1.0\r\nelement vertex 1\r\nproperty double x\r\nend_header\r\n1.5\r\n")
    assert h.elements[0].properties[0].type == "double" and h.n_lines == 5


def test_turk_and_bourke_examples_read():
    """The format's own examples (reference files): values, lists of mixed lengths, several elements."""
    import tempfile
    from pathlib import Path

    d = Path(tempfile.mkdtemp())
    m = read_model(write(d, TURK_CUBE))
    assert m.vertices.shape == (8, 3) and m.faces.shape == (6, 4) and m.comments[0] == "made by Greg Turk"
    assert m.vertices[6].tolist() == [1, 1, 1] and m.faces[1].tolist() == [7, 6, 5, 4]
    h, data = read_ply(write(d, BOURKE_EDGES))
    assert [(e.name, e.count) for e in h.elements] == [("vertex", 8), ("face", 7), ("edge", 5)]
    faces = data["face"]["vertex_index"]
    assert faces.dtype == object and [len(f) for f in faces] == [3, 3, 4, 4, 4, 4, 4]
    assert data["edge"]["vertex1"].tolist() == [0, 1, 2, 3, 2] and data["edge"]["red"].dtype == np.uint8
    m = read_model(write(d, BOURKE_EDGES))
    assert m.colors[4].tolist() == [0, 0, 255] and m.faces[2].tolist() == [7, 6, 5, 4]


# --- round trips -----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", ["binary_little_endian", "binary_big_endian", "ascii"])
@pytest.mark.parametrize("coord_type", ["float", "double"])
def test_points_round_trip(tmp_path, rng, fmt, coord_type):
    X, c, N = cloud(rng)
    p = tmp_path / "pts.ply"
    write_points(p, X, colors=c, normals=N, format=fmt, coord_type=coord_type, comments=["a test"])
    m = read_model(p)
    want = X.astype(np.float32) if coord_type == "float" else X
    # Binary: the bytes are the values. ASCII: 9 significant digits identify a float32 and 17 a float64 uniquely,
    # so the printed precision is exact here too.
    assert np.array_equal(m.vertices, want.astype(float))
    assert np.array_equal(m.normals, N.astype(np.float32).astype(float))
    assert m.colors.dtype == np.uint8 and np.array_equal(m.colors, c)
    assert m.comments == ["a test"] and validate_ply(p).format == fmt
    names = [q.name for q in validate_ply(p).elements[0].properties]
    assert names == ["x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"]


@pytest.mark.parametrize("fmt", ["binary_little_endian", "ascii"])
def test_mesh_round_trip(tmp_path, rng, fmt):
    V, c, N = cloud(rng, 30)
    F = rng.integers(0, 30, size=(40, 3))
    p = tmp_path / "mesh.ply"
    write_mesh(p, V, F, colors=c, normals=N, format=fmt)
    h = validate_ply(p)
    assert [(e.name, e.count) for e in h.elements] == [("vertex", 30), ("face", 40)]
    assert h.elements[1].properties[0].header_line() == "property list uchar int vertex_indices"
    m = read_model(p)
    assert np.array_equal(m.faces, F) and np.array_equal(m.vertices, V.astype(np.float32))
    assert np.array_equal(m.colors, c)


def test_ascii_reads_to_printed_precision(tmp_path):
    p = write(tmp_path, "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty float y\n"
                        "end_header\n0.1234 1e-3\n")
    m = read_ply(p)[1]["vertex"]
    assert m["x"][0] == 0.1234 and m["y"][0] == np.float32(1e-3)


def test_general_elements_ragged_lists_and_empty(tmp_path):
    faces = [np.array([0, 1, 2]), np.array([0, 2, 3, 4]), np.array([1, 2, 3])]
    el = {"vertex": {"x": np.arange(5, dtype=np.float64), "flag": np.array([1, 0, 1, 1, 0], bool)},
          "face": {"vertex_indices": faces, "material": np.array([3, 1, 2], np.int16)},
          "camera": {"f": np.zeros(0, np.float32)}}
    for fmt in ("ascii", "binary_little_endian", "binary_big_endian"):
        p = tmp_path / f"g_{fmt}.ply"
        write_ply(p, el, format=fmt)
        h, d = read_ply(p)
        assert [(e.name, e.count) for e in h.elements] == [("vertex", 5), ("face", 3), ("camera", 0)]
        assert d["vertex"]["x"].dtype == np.float64 and d["vertex"]["flag"].tolist() == [1, 0, 1, 1, 0]
        assert [f.tolist() for f in d["face"]["vertex_indices"]] == [f.tolist() for f in faces]
        assert d["face"]["material"].dtype == np.int16 and d["camera"]["f"].shape == (0,)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_round_trip_any_float32(tmp_path, rng, fmt):
    """Any finite float32, subnormals and extremes included, comes back bit for bit (also in ASCII, %.9g)."""
    bits = rng.integers(0, 2 ** 32, size=3000, dtype=np.uint64).astype(np.uint32)
    X = bits.view(np.float32)
    X = np.concatenate([X[np.isfinite(X)], [0.0, -0.0, 1e-45, -3.4028235e38, 3.4028235e38]]).astype(np.float32)
    X = X[: len(X) // 3 * 3].reshape(-1, 3)
    write_points(tmp_path / "h.ply", X, format=fmt)
    back = read_model(tmp_path / "h.ply").vertices.astype(np.float32)
    assert np.array_equal(back.view(np.uint32), X.view(np.uint32))


def test_sfm_ply_text_is_valid(tmp_path):
    p = write(tmp_path, ply_text(np.array([[1.0, 2.0, 3.5], [0.1, 0.2, 0.3]])))
    assert validate_ply(p).elements[0].count == 2 and read_model(p).vertices[1].tolist() == [0.1, 0.2, 0.3]


def test_written_file_mode_and_no_temporary_left(tmp_path):
    old = os.umask(0o022)
    try:
        write_points(tmp_path / "a.ply", np.zeros((2, 3)))
    finally:
        os.umask(old)
    assert stat.S_IMODE(os.stat(tmp_path / "a.ply").st_mode) == 0o644
    assert sorted(os.listdir(tmp_path)) == ["a.ply"]


# --- bad input to the writers ----------------------------------------------------------------------------------


@pytest.mark.parametrize("kwargs, message", [
    (dict(X=np.zeros((3, 2))), "X must have shape \\(N, 3\\)"),
    (dict(X=[[0, 0, np.nan]]), "X has non-finite coordinates"),
    (dict(X=np.zeros((2, 3)), colors=[[0, 0, 256], [0, 0, 0]]), "colors must lie in 0..255"),
    (dict(X=np.zeros((2, 3)), colors=[[0, 0, -1], [0, 0, 0]]), "colors must lie in 0..255"),
    (dict(X=np.zeros((2, 3)), colors=[[0.5, 0, 0], [0, 0, 0]]), "colors must be integers 0..255.*0..1 colours"),
    (dict(X=np.zeros((2, 3)), colors=np.zeros((3, 3))), "colors must have shape \\(2, 3\\)"),
    (dict(X=np.zeros((2, 3)), normals=np.zeros((2, 2))), "normals must have shape \\(N, 3\\)"),
    (dict(X=np.zeros((2, 3)), normals=[[0, 0, 1], [0, np.inf, 0]]), "normals has non-finite"),
    (dict(X=np.zeros((2, 3)), format="binary"), "format must be one of"),
    (dict(X=np.zeros((2, 3)), coord_type="half"), "coord_type must be"),
])
def test_write_points_bad_input(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        write_points(tmp_path / "bad.ply", **kwargs)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("faces, message", [
    ([[0, 1, 3]], "faces hold vertex indices 0..2 \\(3 vertices\\); got index 3 in face 0"),
    ([[0, 1, 2], [0, -1, 2]], "got index -1 in face 1"),
    ([[0, 1]], "faces must be an integer array of shape \\(F, k\\), k >= 3"),
    ([0, 1, 2], "faces must be an integer array of shape \\(F, k\\)"),
    ([[0, 1, 1.5]], "faces must hold integer vertex indices"),
])
def test_write_mesh_bad_faces(tmp_path, faces, message):
    with pytest.raises(ValueError, match=message):
        write_mesh(tmp_path / "bad.ply", np.eye(3), faces)
    assert os.listdir(tmp_path) == []


def test_write_ply_bad_input(tmp_path):
    with pytest.raises(ValueError, match="element 'v', property 'y' has 3 rows; the element's other properties have 2"):
        write_ply(tmp_path / "b.ply", {"v": {"x": np.zeros(2), "y": np.zeros(3)}})
    with pytest.raises(ValueError, match="element 'v', property 'c' must lie in 0..255 for PLY type uchar"):
        write_ply(tmp_path / "b.ply", {"v": {"c": np.array([1, 300])}}, types={("v", "c"): "uchar"})
    with pytest.raises(ValueError, match="no PLY type"):
        write_ply(tmp_path / "b.ply", {"v": {"c": np.array([1 + 2j])}})
    with pytest.raises(ValueError, match="the folder .* does not exist"):
        write_points(tmp_path / "missing" / "b.ply", np.zeros((1, 3)))
    assert os.listdir(tmp_path) == []


def test_failed_write_removes_the_temporary(tmp_path, monkeypatch):
    def boom(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError, match="No space"):
        write_points(tmp_path / "full.ply", np.zeros((4, 3)))
    assert os.listdir(tmp_path) == []


# --- malformed files -------------------------------------------------------------------------------------------


def test_malformed_ascii_names_file_line_and_element(tmp_path):
    head = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty uchar red\nend_header\n"
    cases = [
        (head + "1 2\n3\n", r"f\.ply, line 8: element 'vertex' row 1 has 1 values; expected 2"),
        (head + "1 2\n", r"f\.ply: element 'vertex' declares 2 rows; the file ends after 1"),
        (head + "1 2\n3 4\n5 6\n", r"f\.ply, line 9: data after the last element"),
        (head + "1 2\nx 4\n", r"f\.ply, line 8: element 'vertex' row 1, property 'x': 'x' is not a valid float"),
        (head + "1 2\n3 256\n", r"line 8: element 'vertex' row 1, property 'red': 256 is out of range for uchar"),
        (head + "1 2\n3 4.5\n", r"line 8: element 'vertex' row 1, property 'red': '4.5' is not a valid uchar"),
    ]
    for text, message in cases:
        with pytest.raises(ValueError, match=message):
            read_ply(write(tmp_path, text))


def test_malformed_lists_and_faces(tmp_path):
    head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n" \
           "element face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n"
    with pytest.raises(ValueError, match=r"line 14: element 'face' row 1, property 'vertex_indices': the list count 4"):
        read_ply(write(tmp_path, head + "3 0 1 2\n4 0 1 2\n"))
    with pytest.raises(ValueError, match=r"f\.ply: element 'face' has vertex index 7; the file has 3 vertices"):
        read_model(write(tmp_path, head + "3 0 1 2\n3 0 1 7\n"))


def test_malformed_binary_names_the_element(tmp_path):
    p = tmp_path / "ok.ply"
    write_mesh(p, np.eye(3), [[0, 1, 2], [2, 1, 0]])
    raw = p.read_bytes()
    with pytest.raises(ValueError, match=r"t\.ply: element 'face', row 1 of 2: the list 'vertex_indices' of 3 "):
        read_ply(write(tmp_path, raw[:-3], "t.ply"))
    with pytest.raises(ValueError, match=r"t\.ply: element 'vertex' needs 36 bytes"):
        read_ply(write(tmp_path, raw[:raw.index(b"end_header\n") + 11 + 20], "t.ply"))
    with pytest.raises(ValueError, match=r"t\.ply: 2 bytes after the last element"):
        read_ply(write(tmp_path, raw + b"\0\0", "t.ply"))
    with pytest.raises(ValueError, match=r"t\.ply: no 'end_header' line"):
        read_ply(write(tmp_path, raw[:30], "t.ply"))


def test_read_model_needs_xyz(tmp_path):
    p = tmp_path / "nv.ply"
    write_ply(p, {"point": {"x": np.zeros(2, np.float32)}})
    with pytest.raises(ValueError, match="no 'vertex' element"):
        read_model(p)
    write_ply(p, {"vertex": {"x": np.zeros(2, np.float32)}})
    with pytest.raises(ValueError, match="lacks x, y or z"):
        read_model(p)
    p.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
                 "end_header\n0 0 0\n0 nan 0\n")
    with pytest.raises(ValueError, match=r"nv\.ply: element 'vertex' has non-finite coordinates .* rows \[1\]"):
        read_model(p)
