"""labutils.model.pointcloud: shapes and bad input, invariants, normals and colours against exact truth (a plane, the
synthetic turntable's bumpy object, the textured snowman), OpenCV's bilinear sampling, PLY round trips, the dinosaur."""
import cv2
import numpy as np
import pytest

from labutils.core.synthetic import make_scene
from labutils.data.ply import read_model, validate_ply
from labutils.model.pointcloud import (
    PointCloud,
    estimate_normals,
    facing_fractions,
    local_pca,
    orient_normals,
    oriented_point_cloud,
    point_colors,
    sample_image,
)
from labutils.model.synthetic import make_textured_scene
from labutils.twoview.triangulation import triangulate_multiview


def blob_normals(X):
    """Exact outward normals of make_scene's turntable object X = s·A·d·b(d) (d on the unit sphere, A = diag(1, .7,
    1.4), b(d) = 1 + .15 sin 3d₀ cos 2d₁ + .1 sin 4d₂): the cross product of X's derivatives along two tangents of d."""
    A = np.array([1.0, 0.7, 1.4])
    d = X / A
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    b = 1 + 0.15 * np.sin(3 * d[:, 0]) * np.cos(2 * d[:, 1]) + 0.1 * np.sin(4 * d[:, 2])
    grad = np.stack([0.45 * np.cos(3 * d[:, 0]) * np.cos(2 * d[:, 1]), -0.3 * np.sin(3 * d[:, 0]) * np.sin(2 * d[:, 1]),
                     0.4 * np.cos(4 * d[:, 2])], axis=1)
    u = np.cross(d, np.where(np.abs(d[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(d, u)
    du = A * (u * b[:, None] + d * np.einsum("ij,ij->i", grad, u)[:, None])
    dv = A * (v * b[:, None] + d * np.einsum("ij,ij->i", grad, v)[:, None])
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(np.einsum("ij,ij->i", n, d / A)[:, None] < 0, -n, n)


@pytest.fixture(scope="module")
def turntable():
    s = make_scene(1500, 24, layout="turntable", noise_px=0, rng=np.random.default_rng(3))
    return s, blob_normals(s.X)


@pytest.fixture(scope="module")
def snowman():
    s = make_textured_scene(12, rng=np.random.default_rng(0), image_size=(200, 150), f=260.0, noise=1.0)
    X, n = s.surface_points(1500, rng=np.random.default_rng(1))
    vis = s.visibility(X, n)
    seen = vis.any(axis=0)
    return s, X[seen], n[seen], vis[:, seen]


# ---------------------------------------------------------------------------------------------- shapes, bad input
def test_shapes(turntable):
    s, _ = turntable
    pca = local_pca(s.X, k=10)
    assert pca.normals.shape == s.X.shape and pca.eigenvalues.shape == s.X.shape and pca.neighbours.shape == (
        len(s.X), 10)
    assert np.all(pca.neighbours[:, 0] == np.arange(len(s.X)))          # each point is its own nearest neighbour
    cloud = oriented_point_cloud(s.X, s.K, s.R, s.t, s.visible)
    assert cloud.normals.shape == s.X.shape and cloud.colors is None and cloud.index.tolist() == list(range(len(s.X)))


@pytest.mark.parametrize("call, words", [
    (lambda s: local_pca(s.X.T, k=5), "X must have shape (N, 3)"),
    (lambda s: local_pca(s.X, k=2), "k must be an integer >= 3"),
    (lambda s: local_pca(s.X[:5], k=6), "only 5 points"),
    (lambda s: local_pca(np.outer(np.arange(10.0), [1, 2, 3]), k=4), "lie on a line"),
    (lambda s: orient_normals(s.X, np.ones_like(s.X), s.R, s.t, s.visible), "unit vectors"),
    (lambda s: orient_normals(s.X, estimate_normals(s.X), s.R, s.t, s.visible.T), "transposed"),
    (lambda s: orient_normals(s.X, estimate_normals(s.X), s.R, s.t, s.visible.astype(int)), "boolean"),
    (lambda s: orient_normals(s.X, estimate_normals(s.X), s.R, s.t, np.zeros_like(s.visible)), "seen by no view"),
    (lambda s: orient_normals(s.X, estimate_normals(s.X), s.R, s.t.T, s.visible), "t must have shape"),
    (lambda s: orient_normals(s.X, estimate_normals(s.X), s.R * 2, s.t, s.visible), "not a rotation"),
    (lambda s: point_colors(s.X, [None] * 3, s.K, s.R, s.t, s.visible), "images has 3 entries for 24 views"),
    (lambda s: point_colors(s.X, [None] * 24, s.K, s.R, s.t, s.visible), "gets no colour"),
    (lambda s: sample_image(np.zeros((4, 4, 3)), [[1, 2, 3]]), "x must have shape (N, 2)"),
])
def test_bad_input_is_a_clear_error(turntable, call, words):
    with pytest.raises(ValueError) as exc:
        call(turntable[0])
    assert words in str(exc.value)


def test_unregistered_views_are_skipped_but_may_not_see(turntable):
    s, _ = turntable
    R, t = s.R.copy(), s.t.copy()
    R[0], t[0] = np.nan, np.nan
    vis = s.visible.copy()
    with pytest.raises(ValueError, match="view 0 is not registered"):
        orient_normals(s.X, estimate_normals(s.X), R, t, vis)
    vis[0] = False
    ok = vis.any(axis=0)
    n = orient_normals(s.X[ok], estimate_normals(s.X[ok]), R, t, vis[:, ok])
    assert np.isfinite(n).all()
    R[1, 0, 0] = np.nan
    with pytest.raises(ValueError, match="partly NaN"):
        orient_normals(s.X[ok], n, R, t, vis[:, ok])


# ---------------------------------------------------------------------------------------------- invariants
def test_orientation_ignores_the_input_sign_and_faces_a_camera(turntable):
    s, _ = turntable
    n = estimate_normals(s.X)
    flips = np.where(np.random.default_rng(0).random(len(n)) < 0.5, -1.0, 1.0)[:, None]
    a = orient_normals(s.X, n, s.R, s.t, s.visible)
    b = orient_normals(s.X, n * flips, s.R, s.t, s.visible)
    assert np.array_equal(a, b)
    assert np.allclose(np.linalg.norm(a, axis=1), 1, atol=1e-12)
    assert facing_fractions(s.X, a, s.R, s.t, s.visible)["any"] == 1.0
    assert facing_fractions(s.X, -a, s.R, s.t, s.visible)["any"] < 0.5       # the other sign fails the check


def test_pca_is_equivariant_under_a_rigid_motion(turntable):
    s, _ = turntable
    Q, _ = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))
    a = local_pca(s.X, k=12)
    b = local_pca(s.X @ Q.T + [1.0, -2.0, 3.0], k=12)
    assert np.allclose(np.abs(np.einsum("ij,ij->i", a.normals @ Q.T, b.normals)), 1, atol=1e-8)
    assert np.allclose(a.eigenvalues, b.eigenvalues, atol=1e-12)
    assert np.all((a.variation >= 0) & (a.variation <= 1 / 3 + 1e-12))


# ---------------------------------------------------------------------------------------------- recovery
def test_plane_normals_are_exact():
    g = np.stack(np.meshgrid(np.arange(8.0), np.arange(8.0)), -1).reshape(-1, 2)
    X = np.column_stack([g, 0.3 * g[:, 0] - 0.2 * g[:, 1] + 1])
    n_true = np.array([-0.3, 0.2, 1.0]) / np.linalg.norm([-0.3, 0.2, 1.0])
    n = estimate_normals(X, k=9)
    assert np.abs(np.abs(n @ n_true) - 1).max() < 1e-12
    assert local_pca(X, k=9).variation.max() < 1e-12


def test_turntable_normals_against_the_exact_ones(turntable):
    """Noise-free points on a curved surface: the PCA normal is biased by the curvature over the neighbourhood
    (a k-NN patch of radius r on a surface of curvature radius ρ tilts by about r/ρ: here r ≈ 0.25 ρ at worst,
    so a few degrees); the sign from visibility must be right for >= 99 % of the points."""
    s, n_true = turntable
    n = orient_normals(s.X, estimate_normals(s.X, k=12), s.R, s.t, s.visible)
    cos = np.einsum("ij,ij->i", n, n_true)
    assert (cos > 0).mean() >= 0.99
    assert np.median(np.degrees(np.arccos(np.clip(np.abs(cos), 0, 1)))) < 5.0
    assert facing_fractions(s.X, n, s.R, s.t, s.visible)["any"] >= 0.99


def test_snowman_normals_and_colours(snowman):
    """The textured snowman: exact normals and exact colours (the same in every view). Colours: bilinear samples of
    images with 1 grey level of noise, a median over the views: within a few grey levels except on the stripes'
    steepest slopes (5 % tail)."""
    s, X, n_true, vis = snowman
    cloud = oriented_point_cloud(X, s.K, s.R, s.t, vis, images=s.images, k=12)
    assert (np.einsum("ij,ij->i", cloud.normals, n_true) > 0).mean() >= 0.99
    err = np.abs(cloud.colors.astype(float) - s.colour(X, n_true))
    assert np.median(err) < 3 and np.percentile(err, 95) < 25
    wrong = point_colors(X, s.images[::-1], s.K, s.R, s.t, vis)             # images in the wrong order
    assert np.median(np.abs(wrong - s.colour(X, n_true))) > 4 * np.median(err)


def test_sample_image_agrees_with_opencv():
    rng = np.random.default_rng(2)
    img = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8).astype(np.float32)
    x = rng.uniform([0, 0], [39, 29], size=(200, 2))
    ours = sample_image(img, x)
    cv = cv2.remap(img, x[:, :1].astype(np.float32), x[:, 1:].astype(np.float32), cv2.INTER_LINEAR)[:, 0]
    assert np.abs(ours - cv).max() < 0.05                   # OpenCV interpolates in fixed point (1/32 px steps)
    assert np.isnan(sample_image(img, [[-1.0, 3.0], [39.5, 0.0]])).all()


# ---------------------------------------------------------------------------------------------- PLY
@pytest.mark.parametrize("fmt", ["binary_little_endian", "ascii"])
def test_ply_round_trip(snowman, tmp_path, fmt):
    s, X, _, vis = snowman
    cloud = oriented_point_cloud(X, s.K, s.R, s.t, vis, images=s.images)
    path = tmp_path / "cloud.ply"
    cloud.write_ply(path, format=fmt)
    header = validate_ply(path)
    assert header.format == fmt
    assert header.elements[0].property_names() == ["x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"]
    m = read_model(path)
    assert np.array_equal(m.vertices, X.astype(np.float32)) and np.array_equal(m.colors, cloud.colors)
    assert np.array_equal(m.normals, cloud.normals.astype(np.float32))


def test_ply_without_colours(turntable, tmp_path):
    s, _ = turntable
    PointCloud(s.X, None, None, s.visible, np.arange(len(s.X))).write_ply(tmp_path / "p.ply")
    m = read_model(tmp_path / "p.ply")
    assert m.colors is None and m.normals is None and len(m.vertices) == len(s.X)


# ---------------------------------------------------------------------------------------------- real data
def test_dinosaur_normals_face_their_cameras(dino):
    """The 4,983 real tracks triangulated with the true cameras, kept where they reproject within 2 px."""
    X = triangulate_multiview(dino.P, dino.tracks)
    seen = np.isfinite(dino.tracks[..., 0])
    x = np.einsum("vij,nj->vni", dino.P, np.column_stack([X, np.ones(len(X))]))
    err = np.linalg.norm(x[..., :2] / x[..., 2:] - dino.tracks, axis=-1)
    vis = seen & (err < 2)
    ok = np.isfinite(X[:, 0]) & (vis.sum(0) >= 2)
    n = orient_normals(X[ok], estimate_normals(X[ok], k=12), dino.R, dino.t, vis[:, ok])
    f = facing_fractions(X[ok], n, dino.R, dino.t, vis[:, ok])
    assert f["any"] >= 0.99 and f["pairs"] >= 0.95
    if dino.image_paths:
        images = [dino.image(i) for i in range(0, dino.n_views, 6)]
        sub = vis[::6][:, ok]
        have = sub.any(axis=0)
        col = point_colors(X[ok][have], images, dino.K, dino.R[::6], dino.t[::6], sub[:, have])
        assert col[:, 0].mean() > col[:, 2].mean() + 40      # an orange dinosaur: red well above blue
