"""labutils.model.meshing: bad input, the boundary of tetrahedra (closed, outward), Delaunay meshes of spheres (closed,
outward, bridges carved away)."""
import numpy as np
import pytest

from labutils.model.carving import mesh_volume
from labutils.model.meshing import boundary_faces, delaunay_mesh, face_normals, vertex_normals


def sphere_points(n, centre=(0.0, 0.0, 0.0), radius=1.0):
    """n points spread evenly on a sphere (Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (1 + 5 ** 0.5) * k
    r = np.sqrt(1 - z ** 2)
    return np.asarray(centre) + radius * np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


TETRA = (np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]),
         np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))


def test_mesh_volume_of_a_tetrahedron_from_lists():
    assert mesh_volume(TETRA[0].tolist(), TETRA[1].tolist()) == pytest.approx(1 / 6)


def edges_shared_twice(F):
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, count = np.unique(e, axis=0, return_counts=True)
    return bool(np.all(count == 2))


# ---------------------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("call, words", [
    (lambda: face_normals(np.eye(3), [[0, 1, 3]]), "vertex indices 0..2"),
    (lambda: face_normals(np.eye(3), [[0, 1]]), "(F, 3) integer array"),
    (lambda: face_normals(np.eye(3), [[0, 1, 1]]), "zero area"),
    (lambda: delaunay_mesh(np.column_stack([np.random.default_rng(0).random((20, 2)), np.zeros(20)])), "one plane"),
    (lambda: delaunay_mesh(sphere_points(50), max_edge=1e-3), "no tetrahedron is left"),
    (lambda: delaunay_mesh(sphere_points(50).T), "X must have shape (N, 3)"),
    # mesh_volume checks its faces like every mesh function (labutils.core.validation.as_mesh): F - 1 used to wrap -1 to
    # the last vertex and give a plausible wrong volume; lists, floats and NaN gave IndexError / TypeError / nan
    (lambda: mesh_volume(*TETRA[:1], TETRA[1] - 1), "faces hold vertex indices 0..3; got -1..2"),
    (lambda: mesh_volume(TETRA[0].tolist(), TETRA[1].tolist()[:3] + [[1, 2, 4]]), "vertex indices 0..3; got 0..4"),
    (lambda: mesh_volume(TETRA[0], TETRA[1].astype(float)), "(F, 3) integer array of triangles; got shape (4, 3), "
                                                            "dtype float64"),
    (lambda: mesh_volume(TETRA[0] * [1, 1, np.nan], TETRA[1]), "vertices has non-finite coordinates"),
    (lambda: mesh_volume(TETRA[0], [[0, 1, 2], [0, 1]]), "(F, 3) integer array of triangles"),
    (lambda: mesh_volume(TETRA[0], np.zeros((0, 3), int)), "faces is empty"),
])
def test_bad_input_is_a_clear_error(call, words):
    with pytest.raises(ValueError) as exc:
        call()
    assert words in str(exc.value)


# ---------------------------------------------------------------------------------------------- tetrahedra, Delaunay
def test_boundary_of_one_tetrahedron_faces_out_whatever_its_order():
    P = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    for tet in ([0, 1, 2, 3], [1, 0, 2, 3]):
        F = boundary_faces([tet], P)
        assert len(F) == 4 and edges_shared_twice(F)
        assert mesh_volume(P, F) == pytest.approx(1 / 6)
        assert np.all(np.einsum("ij,ij->i", face_normals(P, F), P[F].mean(1) - P.mean(0)) > 0)


def test_delaunay_mesh_of_a_sphere_is_closed_and_faces_out():
    """Points on a sphere: every tetrahedron of the convex hull has an edge shorter than the diameter, so with no
    filtering the boundary is the convex hull: closed, outward, every point used, volume that of the inscribed
    polyhedron (a little under 4π/3: the chordal gap of n = 400 points is O(1/n) of it)."""
    X = sphere_points(400)
    m = delaunay_mesh(X, max_edge=3.0)
    assert edges_shared_twice(m.faces) and len(m.vertices) == 400 and m.n_removed == 0
    vol = mesh_volume(m.vertices, m.faces)
    assert 0.98 * 4 / 3 * np.pi < vol < 4 / 3 * np.pi
    assert np.array_equal(m.vertices, X[m.point_index])
    assert np.all(np.einsum("ij,ij->i", vertex_normals(m.vertices, m.faces), m.vertices) > 0.99)


def test_long_edges_are_filtered():
    """Two spheres apart: without a limit the hull bridges them; with a limit of a few spacings, two closed pieces."""
    X = np.vstack([sphere_points(300), sphere_points(300, centre=(3.0, 0, 0))])
    bridged = delaunay_mesh(X, max_edge=10.0)
    apart = delaunay_mesh(X, edge_factor=3.0)                  # 3 × the median spacing (≈ 0.2): under the gap, 1
    assert np.abs(bridged.vertices[:, 0] - 1.5).min() > 0.5   # the convex hull: no point between them either
    assert mesh_volume(bridged.vertices, bridged.faces) > 1.5 * mesh_volume(apart.vertices, apart.faces)  # 13.6 : 8.4
    assert apart.max_edge == pytest.approx(3 * apart.spacing)
    assert edges_shared_twice(apart.faces)
    assert mesh_volume(apart.vertices, apart.faces) == pytest.approx(2 * 4 / 3 * np.pi, rel=0.03)
