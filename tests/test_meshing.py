"""labutils.meshing: bad input, the boundary of tetrahedra (closed, outward), Delaunay meshes of a sphere, the depth
buffer against exact ray–plane depths and the carving module's scan conversion, visibility with an occluder, the most
frontal view, and textures against the textured snowman's exact colours."""
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from labutils.carving import mesh_volume, render_silhouette
from labutils.meshing import (
    boundary_faces,
    delaunay_mesh,
    edge_contrast,
    face_normals,
    held_out_error,
    most_frontal_view,
    render_depth,
    texture_vertices,
    vertex_normals,
    vertex_views,
)
from labutils.synthetic import look_at
from labutils.textured_scene import make_textured_scene


def sphere_points(n, centre=(0.0, 0.0, 0.0), radius=1.0):
    """n points spread evenly on a sphere (Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (1 + 5 ** 0.5) * k
    r = np.sqrt(1 - z ** 2)
    return np.asarray(centre) + radius * np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def sphere_mesh(n, centre=(0.0, 0.0, 0.0), radius=1.0):
    V = sphere_points(n, centre, radius)
    F = ConvexHull(V).simplices
    out = np.einsum("ij,ij->i", np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), V[F[:, 0]] - centre) < 0
    F[out] = F[out][:, ::-1]
    return V, F


def edges_shared_twice(F):
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, count = np.unique(e, axis=0, return_counts=True)
    return bool(np.all(count == 2))


@pytest.fixture(scope="module")
def snowman():
    s = make_textured_scene(12, rng=np.random.default_rng(0), image_size=(200, 150), f=260.0, noise=1.0)
    X, n = s.surface_points(3000, rng=np.random.default_rng(1))
    return s, X, n


# ---------------------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("call, words", [
    (lambda: face_normals(np.eye(3), [[0, 1, 3]]), "vertex indices 0..2"),
    (lambda: face_normals(np.eye(3), [[0, 1]]), "(F, 3) integer array"),
    (lambda: face_normals(np.eye(3), [[0, 1, 1]]), "zero area"),
    (lambda: delaunay_mesh(np.column_stack([np.random.default_rng(0).random((20, 2)), np.zeros(20)])), "one plane"),
    (lambda: delaunay_mesh(sphere_points(50), max_edge=1e-3), "no tetrahedron is left"),
    (lambda: delaunay_mesh(sphere_points(50).T), "X must have shape (N, 3)"),
    (lambda: render_depth(np.eye(3) - [0, 0, 2], [[0, 1, 2]], np.eye(3), np.eye(3), np.zeros(3), (4, 4)), "behind"),
    (lambda: render_depth(np.eye(3), [[0, 1, 2]], np.eye(3), np.eye(3), np.zeros(3), (4,)), "image_size"),
    (lambda: most_frontal_view(np.zeros((2, 3)), [[0, 0, 1.0]] * 2, np.ones((3, 3)), np.ones((2, 3), bool)),
     "transposed"),
    (lambda: edge_contrast(np.zeros((3, 3)), [[0, 1, 5]]), "indices into colors"),
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


# ---------------------------------------------------------------------------------------------- the depth buffer
def test_depth_of_a_tilted_plane_is_exact():
    """A square on the plane z = 4 + 0.5 x seen from the origin: every covered pixel's depth is that of the plane
    where its ray meets it (perspective-correct); interpolating z linearly in the image would be off by up to 0.2."""
    K = np.array([[50.0, 0, 32], [0, 50, 24], [0, 0, 1]])
    V = np.array([[-2.0, -2, 3], [2, -2, 5], [2, 2, 5], [-2, 2, 3]])
    depth, face = render_depth(V, [[0, 1, 2], [0, 2, 3]], K, np.eye(3), np.zeros(3), (64, 48))
    r, c = np.nonzero(face >= 0)
    ray = np.linalg.solve(K, np.stack([c, r, np.ones_like(c)]).astype(float))      # z = 1
    z_true = 4 / (1 - 0.5 * ray[0])                                                 # z = 4 + 0.5 x on the ray
    assert len(r) > 500 and np.abs(depth[r, c] - z_true).max() < 1e-9
    assert np.isinf(depth[face < 0]).all()


def test_nearest_surface_wins_and_silhouette_matches_carving(snowman):
    V, F = sphere_mesh(500, centre=(0, 0, 0), radius=1.0)
    V2, F2 = sphere_mesh(500, centre=(0.5, 0, -2.0), radius=0.5)          # a smaller sphere in front of it
    V_all, F_all = np.vstack([V, V2]), np.vstack([F, F2 + len(V)])
    K = np.array([[60.0, 0, 40], [0, 60, 30], [0, 0, 1]])
    R, t = look_at(np.array([0.0, 0, -6]), np.zeros(3), up=(0, -1, 0))
    depth, face = render_depth(V_all, F_all, K, R, t, (80, 60))
    front = face >= len(F)
    assert front.sum() > 50 and np.all(depth[front] < 4.0) and np.all(depth[(face >= 0) & ~front] > 4.9)
    P = K @ np.column_stack([R, t])
    assert np.array_equal(face >= 0, render_silhouette(V_all, F_all, P, (80, 60)))


# ---------------------------------------------------------------------------------------------- visibility, colour
def test_occluded_and_back_facing_vertices_are_not_visible():
    V, F = sphere_mesh(800, radius=1.0)
    V2, F2 = sphere_mesh(300, centre=(0, 0, -2.0), radius=0.4)
    V_all, F_all = np.vstack([V, V2]), np.vstack([F, F2 + len(V)])
    K = np.array([[60.0, 0, 40], [0, 60, 30], [0, 0, 1]])
    R, t = look_at(np.array([0.0, 0, -6]), np.zeros(3), up=(0, -1, 0))
    img = np.full((60, 80, 3), 100, np.uint8)
    vv = vertex_views(V_all, F_all, K, R[None], t[None], [img], buffer_scale=1.0)
    big = np.arange(len(V))
    facing = V[:, 2] < -0.05                                       # the big sphere's side toward the camera
    C, S = np.array([0.0, 0, -6]), np.array([0.0, 0, -2.0])
    miss = np.linalg.norm(np.cross(V - C, S - C), axis=1) / np.linalg.norm(V - C, axis=1)   # ray's distance to S
    assert not vv.visible[0, big][~facing].any()                    # the back is never seen
    assert not vv.visible[0, big][facing & (miss < 0.33)].any()     # nor what the small sphere hides
    clear = facing & (miss > 0.45) & (V[:, 2] < -0.5)               # a margin for the facets; not grazing
    assert clear.sum() > 20 and vv.visible[0, big][clear].all()
    assert vv.inside[0].all()                                       # all project into the image, hidden or not


def test_most_frontal_view_by_construction():
    X = np.zeros((3, 3))
    normals = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    C = np.array([[10.0, 1, 0], [0, 10, 0], [0, 0, 10], [3.0, 0, 0.1]])      # view 3: close, slightly off
    vis = np.ones((4, 3), bool)
    assert most_frontal_view(X, normals, C, vis).tolist() == [3, 1, 2]
    vis[3, 0] = False
    vis[:, 2] = False
    assert most_frontal_view(X, normals, C, vis).tolist() == [0, 1, -1]


def test_texture_of_the_snowman(snowman):
    """The snowman's surface, meshed by Delaunay from exact surface points, coloured three ways. Truth: the colour
    every view sees (albedo × Lambertian shade). The frontal view's colour is one bilinear sample (1 grey level of
    noise) at an exact point: within a few levels. The naive average mixes in the views where the vertex is hidden
    behind another sphere: clearly worse, and it blurs (less contrast)."""
    s, X, n = snowman
    m = delaunay_mesh(X)
    assert mesh_volume(m.vertices, m.faces) == pytest.approx(sum(4 / 3 * np.pi * s.spheres[:, 3] ** 3), rel=0.1)
    vv = vertex_views(m.vertices, m.faces, s.K, s.R, s.t, s.images)
    truth = s.colour(m.vertices, n[m.point_index])
    err = {}
    for method in ("frontal", "visible", "average"):
        tex = texture_vertices(vv, method=method)
        ok = tex.coloured
        err[method] = np.median(np.abs(tex.colors[ok].astype(float) - truth[ok]))
    assert err["frontal"] < 4 and err["average"] > 2 * err["frontal"]
    frontal = texture_vertices(vv, method="frontal")
    assert frontal.n_uncoloured < 0.05 * len(m.vertices)
    assert np.all(vv.visible[frontal.view[frontal.coloured], np.flatnonzero(frontal.coloured)])
    assert edge_contrast(frontal.colors, m.faces) > edge_contrast(texture_vertices(vv, method="average").colors,
                                                                   m.faces)
    held = held_out_error(vv, [0, 5], method="frontal")
    assert np.all(held < held_out_error(vv, [0, 5], method="average"))
    with pytest.raises(ValueError, match="method must be"):
        texture_vertices(vv, method="best")
    with pytest.raises(ValueError, match="exclude holds view indices"):
        texture_vertices(vv, exclude=[12])
