"""labutils.model.texturing: bad input, the depth buffer against exact ray–plane depths and the carving module's scan
conversion, visibility with an occluder, the most frontal view, and textures against the textured snowman's exact
colours."""
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from labutils.core.synthetic import look_at
from labutils.model.carving import mesh_volume, render_silhouette
from labutils.model.meshing import delaunay_mesh
from labutils.model.synthetic import make_textured_scene
from labutils.model.texturing import (
    edge_contrast,
    held_out_error,
    most_frontal_view,
    render_depth,
    texture_vertices,
    vertex_views,
)


def sphere_mesh(n, centre=(0.0, 0.0, 0.0), radius=1.0):
    """A triangulated sphere: n points of a Fibonacci lattice, their convex hull turned outward."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (1 + 5 ** 0.5) * k
    r = np.sqrt(1 - z ** 2)
    V = np.asarray(centre) + radius * np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
    F = ConvexHull(V).simplices
    out = np.einsum("ij,ij->i", np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), V[F[:, 0]] - centre) < 0
    F[out] = F[out][:, ::-1]
    return V, F


@pytest.fixture(scope="module")
def snowman():
    s = make_textured_scene(12, rng=np.random.default_rng(0), image_size=(200, 150), f=260.0, noise=1.0)
    X, n = s.surface_points(3000, rng=np.random.default_rng(1))
    return s, X, n


@pytest.mark.parametrize("call, words", [
    (lambda: render_depth(np.eye(3) - [0, 0, 2], [[0, 1, 2]], np.eye(3), np.eye(3), np.zeros(3), (4, 4)), "behind"),
    (lambda: render_depth(np.eye(3), [[0, 1, 2]], np.eye(3), np.eye(3), np.zeros(3), (4,)), "image_size"),
    (lambda: most_frontal_view(np.zeros((2, 3)), [[0, 0, 1.0]] * 2, np.ones((3, 3)), np.ones((2, 3), bool)),
     "transposed"),
    (lambda: edge_contrast(np.zeros((3, 3)), [[0, 1, 5]]), "faces hold vertex indices 0..2; got 0..5"),
    (lambda: edge_contrast(np.zeros((3, 3)), [[0, 1, 2.0]]), "(F, 3) integer array of triangles"),  # was IndexError
    (lambda: edge_contrast([[0, 0, 0], [9, 9, 9], [0, 0, np.nan]], [[0, 1, 2]]), "colors has non-finite"),  # was nan
    (lambda: edge_contrast(np.zeros((3, 3)), [[0, 1, -1]]), "faces hold vertex indices 0..2; got -1..1"),
])
def test_bad_input_is_a_clear_error(call, words):
    with pytest.raises(ValueError) as exc:
        call()
    assert words in str(exc.value)


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
