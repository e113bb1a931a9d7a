"""Space carving: bad input, invariants, recovery of a synthetic snowman's visual hull, OpenCV as a reference,
the real temple's box; the command line through subprocess."""
import os
import stat
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from labutils.data.middlebury import read_par, write_par
from labutils.data.ply import read_model, validate_ply
from labutils.model.carving import (
    Carving,
    VoxelGrid,
    background_model,
    bounding_box_from_silhouettes,
    carve,
    choose_threshold,
    clean_mask,
    colour_distance,
    inside_silhouette,
    mask_iou,
    mesh_volume,
    project_with_depth,
    render_silhouette,
    segment_views,
    signed_distance_map,
    silhouette,
    silhouette_ious,
    surface_mesh,
    threshold_ladder,
    unsure_views,
    unsure_warning,
)
from labutils.model.carving.silhouettes import QUANTISATION
from labutils.model.synthetic import make_snowman

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def scene():
    return make_snowman(16, rng=np.random.default_rng(1), image_size=(200, 150), f=260.0)


@pytest.fixture(scope="module")
def carved(scene):
    grid = VoxelGrid.from_box(bounding_box_from_silhouettes(scene.masks, scene.P), 56)
    return carve(scene.masks, scene.P, grid)


def px_margin(scene, X):
    """Per point: the smallest distance, in pixels (approximately: the angle times f), between its ray and a
    sphere's silhouette boundary over all views; a pixel grid can only misjudge points with a small margin."""
    f = scene.K[0, 0, 0]
    out = np.full(len(X), np.inf)
    for C in scene.C:
        d = (X - C) / np.linalg.norm(X - C, axis=1, keepdims=True)
        for S, r in zip(scene.spheres[:, :3], scene.spheres[:, 3]):
            v = S - C
            dist = np.sqrt(np.maximum(v @ v - (d @ v) ** 2, 0))
            out = np.minimum(out, np.abs(dist - r) / np.linalg.norm(v) * f)
    return out


# --- shapes and bad input ------------------------------------------------------------------------------------------


def test_bad_input_raises_naming_the_argument(scene):
    P, masks = scene.P, scene.masks
    grid = VoxelGrid.from_box(scene.box, 8)
    with pytest.raises(ValueError, match="masks has 15 silhouettes for 16 cameras"):
        carve(masks[:-1], P, grid)
    with pytest.raises(ValueError, match=r"P must be a \(V, 3, 4\) stack"):
        carve(masks, P[:, :, :3], grid)
    bad = P.copy()
    bad[3, 0, 0] = np.nan
    with pytest.raises(ValueError, match="P has non-finite entries"):
        carve(masks, bad, grid)
    bad = P.copy()
    bad[2, :, :3] = 0
    with pytest.raises(ValueError, match=r"P\[2\] has a singular left 3x3 block"):
        carve(masks, bad, grid)
    with pytest.raises(ValueError, match=r"masks\[1\] must be a \(H, W\) boolean mask"):
        carve([masks[0], masks[1].astype(float) * 0.5] + list(masks[2:]), P, grid)
    with pytest.raises(ValueError, match="grid must be a VoxelGrid"):
        carve(masks, P, scene.box)
    with pytest.raises(ValueError, match="box must be"):
        VoxelGrid.from_box([[0, 0, 0], [1, 0, 1]], 10)
    with pytest.raises(ValueError, match=r"n \(voxels along the longest side\) must be >= 2"):
        VoxelGrid.from_box(scene.box, 1)
    with pytest.raises(ValueError, match=r"image must be an RGB image, a \(H, W, 3\) uint8 array"):
        colour_distance(scene.images[0].astype(float), background_model(scene.images[:2]))
    with pytest.raises(ValueError, match=r"images\[1\] must be an RGB image"):
        background_model([scene.images[0], scene.images[1][..., 0]])
    with pytest.raises(ValueError, match="b has shape"):
        mask_iou(masks[0], masks[0][:-1])
    with pytest.raises(ValueError, match="both masks are empty"):
        mask_iou(np.zeros((3, 3), bool), np.zeros((3, 3), bool))
    with pytest.raises(ValueError, match=r"mask must be a \(H, W\) boolean mask with H, W > 0"):
        clean_mask(np.zeros((0, 3), bool))         # cv2.connectedComponentsWithStats crashed python on it
    with pytest.raises(ValueError, match=r"masks\[0\] must be a \(H, W\) boolean mask with H, W > 0"):
        carve([np.zeros((0, 5), np.uint8)] + list(masks[1:]), P, grid)
    with pytest.raises(ValueError, match="X must have shape"):
        inside_silhouette(np.zeros((4, 2)), P[0], masks[0])
    with pytest.raises(ValueError, match="faces hold vertex indices"):
        render_silhouette(np.zeros((3, 3)) + [0, 0, 0.3], [[0, 1, 3]], P[0], (20, 10))
    with pytest.raises(ValueError, match="image_size must be"):
        render_silhouette(np.eye(3) + [0, 0, 3], [[0, 1, 2]], P[0], (20, -1))
    with pytest.raises(ValueError, match=r"faces hold vertex indices 0..2; got -1..1"):
        render_silhouette(np.eye(3) + [0, 0, 3], [[0, 1, -1]], P[0], (20, 10))
    assert not render_silhouette(np.eye(3) + [0, 0, 3], np.zeros((0, 3), int), P[0], (20, 10)).any()   # no faces
    model = background_model(scene.images[:2])
    for call, message in [
        (lambda: silhouette(scene.images[0], model, threshold=np.nan), "threshold must be a finite number"),
        (lambda: silhouette(scene.images[0], model, threshold=-1), "threshold must be >= 0"),
        (lambda: colour_distance(scene.images[0], "blue"), "model must be a BackgroundModel"),
        (lambda: background_model(scene.images[:2], border_px=0), "border_px must be >= 1"),
        (lambda: background_model(scene.images[:2], n_clusters=0), "n_clusters must be >= 1"),
        (lambda: background_model(scene.images[:2], false_alarm=0), "false_alarm must be > 0"),
        (lambda: segment_views(scene.images[:3], P), "images has 3 views for the 16 cameras of P"),
        (lambda: unsure_views([[0.9]]), r"agreement must be a \(V,\) array"),
        (lambda: threshold_ladder(0.0), "threshold must be > 0"),
        (lambda: background_model([]), "images is empty"),
        (lambda: clean_mask(masks[0], min_component=2), "min_component must be <= 1"),
        (lambda: VoxelGrid.from_box(scene.box, "many"), "n .* must be a number"),
        (lambda: carve(masks, P, grid, band_voxels=0), "band_voxels must be > 0"),
        (lambda: surface_mesh(masks), "carving must be a Carving"),
        (lambda: choose_threshold([np.zeros((4, 4))] * 16, P, ()), "candidates is empty"),
    ]:
        with pytest.raises(ValueError, match=message):
            call()


def test_behind_the_camera_and_outside_the_image():
    P = np.hstack([np.eye(3), np.zeros((3, 1))])
    mask = np.ones((5, 5), bool)
    X = np.array([[1.0, 1.0, 1.0], [-1.0, -1.0, -1.0], [10.0, 1.0, 1.0], [-0.4, -0.4, 1.0], [-0.6, 0, 1.0]])
    # in front and inside; behind (it would project to (1, 1)); right of the image; rounds to pixel 0; left of it
    assert inside_silhouette(X, P, mask).tolist() == [True, False, False, True, False]
    x, depth = project_with_depth(-2 * P, X)          # P's scale and sign do not change pixels or depths
    assert np.allclose(depth, [1, -1, 1, 1, 1]) and np.allclose(x[0], [1, 1])
    with pytest.raises(ValueError, match="reaches behind the camera"):
        render_silhouette(X[:3], [[0, 1, 2]], P, (5, 5))


def test_empty_views_are_reported(scene):
    masks = [m.copy() for m in scene.masks]
    masks[4][:] = False
    with pytest.raises(ValueError, match=r"masks\[4\] is empty"):
        bounding_box_from_silhouettes(masks, scene.P)
    grid = VoxelGrid.from_box(scene.box, 12)
    c = carve(masks, scene.P, grid)
    assert c.n_occupied == 0
    with pytest.raises(ValueError, match="every voxel was carved away"):
        surface_mesh(c)


def test_parallel_cameras_cannot_bound_the_object():
    K = np.array([[100.0, 0, 50], [0, 100, 50], [0, 0, 1]])
    P = np.stack([K @ np.hstack([np.eye(3), [[x], [0], [5]]]) for x in (0.0, 0.5, 1.0)])
    masks = [np.pad(np.ones((10, 10), bool), 45) for _ in range(3)]
    with pytest.raises(ValueError, match="nearly\\) parallel"):
        bounding_box_from_silhouettes(masks, P)


# --- invariants ----------------------------------------------------------------------------------------------------


def test_occupancy_is_the_and_of_the_per_view_test(scene, carved):
    """carve() keeps exactly the voxels whose centre projects inside every mask (the exercise's loop)."""
    X = carved.grid.centres()
    keep = np.ones(len(X), bool)
    for P, m in zip(scene.P, scene.masks):
        keep &= inside_silhouette(X, P, m)
    assert np.array_equal(keep.reshape(carved.grid.shape), carved.occupied)
    assert np.array_equal(carved.occupied, carved.field > 0) and carved.field.min() >= -carved.band


def test_more_views_carve_more_and_scale_of_P_does_not_matter(scene, carved):
    fewer = carve(scene.masks[::2], scene.P[::2], carved.grid)
    assert np.all(carved.occupied <= fewer.occupied) and fewer.n_occupied > carved.n_occupied
    scaled = carve(scene.masks, -3.0 * scene.P, carved.grid)
    assert np.array_equal(scaled.occupied, carved.occupied)


def test_signed_distance_map_sign_and_values():
    m = np.zeros((40, 50), bool)
    m[10:30, 5:45] = True
    D = signed_distance_map(m)
    assert np.array_equal(D > 0, m) and np.all(np.abs(D) >= 0.5)
    assert D[20, 25] == 9.5 and D[20, 5] == 0.5 and D[20, 4] == -0.5 and D[0, 25] == -9.5
    edge = np.zeros((10, 10), bool)
    edge[:, :5] = True                                  # touching the image border: the border is the boundary
    assert signed_distance_map(edge)[5, 0] == 0.5


def test_clean_mask_keeps_big_holes_and_border_gaps():
    m = np.zeros((60, 60), bool)
    m[10:50, 10:50] = True
    m[20:40, 20:40] = False           # a big hole (a see-through gap, 25 % of the object): kept
    m[12, 12] = False                 # a pinhole: filled
    m[30, 45:50] = False              # a notch open to the outside: not a hole, kept
    m[2:4, 2:4] = True                # a speck: removed
    c = clean_mask(m)
    assert not c[30, 30] and c[12, 12] and not c[30, 47] and not c[2, 2]


def test_mesh_is_closed_and_outward(carved):
    V, F, N = surface_mesh(carved)
    edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)                          # every edge shared by exactly two triangles: closed
    assert mesh_volume(V, F) > 0                        # counter-clockwise seen from outside
    n_face = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    assert np.mean(np.einsum("ij,ij->i", n_face, N[F].mean(axis=1)) > 0) > 0.99   # faces agree with the normals
    assert np.allclose(np.linalg.norm(N, axis=1), 1, atol=1e-5)


# --- recovery on synthetic truth -----------------------------------------------------------------------------------


def test_masks_from_colour_match_the_true_silhouettes(scene):
    model = background_model(scene.images)
    for img, truth in zip(scene.images[::3], scene.masks[::3]):
        m = silhouette(img, model)
        # noise of 2 grey levels against a contrast of ~100: only pixels the silhouette's edge cuts can differ
        assert np.count_nonzero(m != truth) <= 0.01 * truth.sum()
        assert mask_iou(m, truth) > 0.99


def test_carving_recovers_the_exact_visual_hull(scene, carved):
    """Noise-free: the carved voxels are the exact (analytic) visual hull's, except voxels whose projection
    lies within half a pixel's diagonal (0.71 px) of a silhouette's boundary in some view: the nearest pixel's
    centre may then fall on the other side."""
    X = carved.grid.centres()
    hull = scene.inside_hull(X)
    occ = carved.occupied.ravel()
    wrong = hull != occ
    margin = px_margin(scene, X)
    assert wrong.any() and np.all(margin[wrong] < 0.75)
    assert wrong.sum() < 0.5 * np.count_nonzero(margin < 0.75)
    assert np.all(occ[scene.inside_object(X) & (margin >= 0.75)])      # the hull contains the object


def test_box_from_silhouettes_holds_the_object(scene):
    box = bounding_box_from_silhouettes(scene.masks, scene.P)
    assert np.all(box[0] <= scene.box[0]) and np.all(box[1] >= scene.box[1])
    # not much more: the hull is wider than the object above the head (no camera looks from above), plus the
    # coarse search's margin of 1.5 voxels of 1/40 of the box (≈ 4 %) on each side
    assert np.all(box[1] - box[0] < 1.35 * (scene.box[1] - scene.box[0]))


def test_surface_silhouettes_overlap_the_masks(scene, carved):
    V, F, _ = surface_mesh(carved)
    ious = silhouette_ious(V, F, scene.masks, scene.P)
    # voxels of 1/56 of the box (≈ 4 px here) and a surface within a pixel of the silhouettes: the boundary pixels
    # lost or gained are a few % of the area
    assert ious.min() > 0.96, ious
    true_volume = carved.grid.voxel_size ** 3 * scene.inside_hull(carved.grid.centres()).sum()
    assert abs(mesh_volume(V, F) / true_volume - 1) < 0.03


def test_render_silhouette_of_a_sphere_is_its_exact_disc(scene):
    """The mesh of one sphere (fine grid) renders to the analytic silhouette within a boundary pixel."""
    one = make_snowman(4, rng=np.random.default_rng(0), image_size=(120, 90), f=160.0,
                       spheres=[[0.0, 0.0, 0.3, 0.3]])
    ball = Carving(grid=VoxelGrid.from_box([[-0.32, -0.32, -0.02], [0.32, 0.32, 0.62]], 64), occupied=None,
                   field=None, band=1.0)
    ball.field = (0.3 - np.linalg.norm(ball.grid.centres() - [0, 0, 0.3], axis=1)).reshape(ball.grid.shape)
    ball.occupied = ball.field > 0
    V, F, _ = surface_mesh(ball)
    assert abs(mesh_volume(V, F) / (4 / 3 * np.pi * 0.3 ** 3) - 1) < 0.01
    for P, m in zip(one.P, one.masks):
        r = render_silhouette(V, F, P, (120, 90))
        ring = cv2.dilate(m.astype(np.uint8), np.ones((3, 3))) & ~cv2.erode(m.astype(np.uint8), np.ones((3, 3)))
        assert np.all((r == m) | ring.astype(bool))


def test_choose_threshold_prefers_consistent_masks(scene):
    model = background_model(scene.images)
    d = [colour_distance(im, model) for im in scene.images]
    # the median colour distance on the object cuts the darker half of each sphere out of the masks
    cut = float(np.median(np.concatenate([di[m] for di, m in zip(d, scene.masks)])))
    low = (model.threshold, 2 * model.threshold)
    best, scores = choose_threshold(d, scene.P, low + (cut,), every=4)
    assert best in low and scores[2, 0] < scores[:2, 0].min() - 0.1, scores


# --- silhouettes that generalise: lightness, several tones, a self-check ----------------------------------------------


SCENES = {   # object's paint, background (one colour, or a wall above a table)
    "light grey on black": ((190, 190, 190), (10, 10, 10)),
    "dark grey on white": ((50, 50, 50), (220, 220, 220)),
    "black on grey": ((25, 25, 25), (150, 150, 150)),
    "red on green": ((200, 40, 40), (40, 150, 60)),
    "blue on a black wall and a white table": ((50, 80, 200), [(15, 15, 15), (200, 200, 200)]),
    "light grey on a black wall and a dark grey table": ((200, 200, 200), [(10, 10, 10), (45, 45, 45)]),
    "yellow on a blue wall and a white table": ((230, 200, 60), [(60, 75, 170), (210, 210, 210)]),
}


@pytest.mark.parametrize("name", list(SCENES))
def test_rendered_objects_of_several_colours_on_several_backgrounds(name):
    """Lightness counts as much as hue: every view's mask matches the exact silhouette, the model carved from the
    masks explains every one of them (IoU >= 0.9), and the self-check is sure of every view."""
    colour, background = SCENES[name]
    sc = make_snowman(8, rng=np.random.default_rng(3), image_size=(100, 75), f=130.0, colour=colour,
                      background=background, noise=4.0, elevations=(20.0,))
    r = segment_views(sc.images, sc.P, n=24, n_check=40)
    truth = [mask_iou(m, t) for m, t in zip(r.masks, sc.masks)]
    assert min(truth) > 0.97, (name, truth)
    assert r.unsure.size == 0 and r.agreement.min() >= 0.9, (name, r.agreement)
    assert r.model.threshold <= r.threshold <= r.candidates[-1]
    grid = VoxelGrid.from_box(bounding_box_from_silhouettes(r.masks, sc.P), 48)
    V, F, _ = surface_mesh(carve(r.masks, sc.P, grid))
    assert silhouette_ious(V, F, r.masks, sc.P).min() >= 0.9


def test_background_of_two_tones_gets_a_cluster_each():
    sc = make_snowman(4, rng=np.random.default_rng(4), image_size=(80, 60), f=105.0, colour=(230, 200, 60),
                      background=[(15, 15, 15), (200, 200, 200)], noise=2.0)
    model = background_model(sc.images, n_clusters=4)
    L = np.sort(model.means[:, 0])
    assert L[0] < 15 and L[-1] > 70              # the black wall and the white table are both background
    d = colour_distance(sc.images[0], model)
    assert np.all(d[~sc.masks[0]] < 30 * model.threshold) and np.median(d[sc.masks[0]]) > 10 * model.threshold
    assert abs(np.mean(colour_distance(sc.images[1], model)[:4] > model.threshold) - 0.01) < 0.03


@pytest.mark.parametrize("seed", [5, 7])
def test_ambiguous_colours_are_found_unsure_then_refined(tmp_path, seed):
    """A grey object whose shaded side takes the grey of the table it stands on: no colour threshold can cut it
    out, and the check says so (views unsure, one warning line); GrabCut from those masks, with spatial
    coherence, then recovers the true silhouettes (IoU >= 0.9 in every view: 0.95-0.97 measured, 0.86 before) —
    in the library and in the command line, which says that it refined them."""
    sc = make_snowman(8, rng=np.random.default_rng(seed), image_size=(100, 75), f=130.0, colour=(200, 200, 200),
                      background=[(10, 10, 10), (90, 90, 90)], noise=2.0, elevations=(20.0,))
    plain = segment_views(sc.images, sc.P, n=24, n_check=40, refine=False)
    assert plain.unsure.size >= 4 and plain.warning().startswith(f"unsure silhouettes in {plain.unsure.size} of 8")
    r = segment_views(sc.images, sc.P, n=24, n_check=40)
    assert r.refined and r.unsure.size == 0
    assert min(mask_iou(m, t) for m, t in zip(r.masks, sc.masks)) >= 0.9
    par = write_scene(tmp_path, sc)
    out = _cli(par.name, "--out", "hull.ply", "--grid", 24, cwd=tmp_path)
    assert out.returncode == 0 and (tmp_path / "hull.ply").is_file(), out.stderr
    assert "every mask refined by GrabCut" in out.stderr and "warning" not in out.stderr


def test_unsure_views_and_warning():
    assert unsure_views([0.95, 0.5, np.nan, 0.9]).tolist() == [1, 2]          # NaN (no model) is unsure too
    assert unsure_warning([0.99, 0.95]) is None
    w = unsure_warning(np.linspace(0.5, 0.8, 7))
    assert w.startswith("unsure silhouettes in 7 of 7 views: 0 (IoU 0.50 with") and "and 3 more" in w
    assert "\n" not in w


# --- the reference library -----------------------------------------------------------------------------------------


def test_projection_agrees_with_opencv(scene):
    X = np.random.default_rng(0).normal(size=(50, 3)) * 0.3
    for K, R, t, P in zip(scene.K[:4], scene.R[:4], scene.t[:4], scene.P[:4]):
        x, depth = project_with_depth(P, X)
        x_cv, _ = cv2.projectPoints(X, cv2.Rodrigues(R)[0], t, K, None)
        assert np.abs(x - x_cv[:, 0]).max() < 1e-9
        assert np.allclose(depth, X @ R[2] + t[2])


def test_colour_distance_is_the_mahalanobis_distance_in_opencv_lab():
    """Brute force from OpenCV's CIELAB: each pixel's Mahalanobis distance to the nearest cluster of the border's
    colours, with the cluster's covariance (plus the quantisation) inverted by numpy."""
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, size=(20, 30, 3), dtype=np.uint8)
    img[:4] = img[-4:] = (30, 40, 50)
    img[:, :4] = (200, 190, 20)
    img[:, -4:] = (200, 190, 20)
    img[:, :4, 0] += rng.integers(0, 9, size=(20, 4), dtype=np.uint8)         # a spread along red
    model = background_model([img], n_clusters=2)
    lab = cv2.cvtColor(img.astype(np.float32) / 255, cv2.COLOR_RGB2LAB).reshape(-1, 3).astype(float)
    border = np.zeros((20, 30), bool)
    border[:4] = border[-4:] = True
    border[:, :4] = border[:, -4:] = True
    grey = np.all(img == (30, 40, 50), axis=-1)
    groups = [lab[(border & grey).ravel()], lab[(border & ~grey).ravel()]]
    brute = np.full(len(lab), np.inf)
    for g in groups:
        inv = np.linalg.inv(np.cov(g.T) + QUANTISATION ** 2 * np.eye(3))
        z = lab - g.mean(axis=0)
        brute = np.minimum(brute, np.sqrt(np.einsum("ij,jk,ik->i", z, inv, z)))
    assert model.n_clusters == 2
    assert np.allclose(colour_distance(img, model).ravel(), brute, rtol=1e-4, atol=1e-3)
    d_border = colour_distance(img, model)[border]
    assert model.threshold == pytest.approx(np.quantile(d_border, 0.99), rel=1e-4)


# --- real data -----------------------------------------------------------------------------------------------------


def test_temple_box_from_silhouettes():
    from labutils.data.loaders import TEMPLE_BOX, DataNotFoundError, load_temple

    try:
        temple = load_temple()
    except DataNotFoundError as exc:
        pytest.skip(f"real data missing: {str(exc).splitlines()[0]}")
    idx = list(range(0, temple.n_views, 4))
    images = [temple.image(i) for i in idx]
    model = background_model(images)
    masks = [silhouette(im, model) for im in images]
    box = bounding_box_from_silhouettes(masks, temple.P[idx])
    # the data set's tight box lies inside ours, and ours is at most 40 % wider on any axis (the hull is
    # wider than the object, plus the margin)
    assert np.all(box[0] <= TEMPLE_BOX[0] + 1e-3) and np.all(box[1] >= TEMPLE_BOX[1] - 1e-3), box
    assert np.all(box[1] - box[0] < 1.4 * (TEMPLE_BOX[1] - TEMPLE_BOX[0])), box


@pytest.fixture(scope="module")
def temple_views():
    from labutils.data.loaders import DataNotFoundError, load_temple

    try:
        temple = load_temple()
    except DataNotFoundError as exc:
        pytest.skip(f"real data missing: {str(exc).splitlines()[0]}")
    idx = list(range(0, temple.n_views, 4))                  # 12 views at half size: seconds, not minutes
    return [temple.image(i)[::2, ::2] for i in idx], np.diag([0.5, 0.5, 1.0]) @ temple.P[idx]


TEMPLE_VARIANTS = {
    "colour": lambda a: a,
    "darkened": lambda a: np.round(a * 0.5).astype(np.uint8),
    "brightened": lambda a: np.clip(np.round(a * 1.6), 0, 255).astype(np.uint8),
    "inverted (dark on light)": lambda a: 255 - a,
}


@pytest.mark.parametrize("variant", list(TEMPLE_VARIANTS))
def test_temple_silhouettes_agree_in_every_view(temple_views, variant):
    images, P = temple_views
    r = segment_views([TEMPLE_VARIANTS[variant](im) for im in images], P, n=32, n_check=64)
    assert r.unsure.size == 0 and r.agreement.min() >= 0.9, (variant, r.agreement)


def test_grey_temple_is_refined_where_a_threshold_is_unsure(temple_views):
    """In grey, the temple's shaded faces and the glow of the black cloth around it have the same lightness: no
    colour threshold separates them, and the check finds unsure views; GrabCut from those masks decides the edges
    with spatial coherence, after which every view agrees (IoU >= 0.9) and the masks are those of the colour
    images (IoU >= 0.9 in every view)."""
    images, P = temple_views
    grey = [np.repeat(cv2.cvtColor(im, cv2.COLOR_RGB2GRAY)[..., None], 3, axis=-1) for im in images]
    plain = segment_views(grey, P, n=32, n_check=64, refine=False)
    assert plain.unsure.size >= 1 and plain.warning() is not None
    r = segment_views(grey, P, n=32, n_check=64)
    colour = segment_views(images, P, n=32, n_check=64)
    assert r.refined and r.unsure.size == 0 and r.agreement.min() >= 0.9, r.agreement
    assert not colour.refined and min(mask_iou(a, b) for a, b in zip(r.masks, colour.masks)) >= 0.9


def test_dino_silhouettes_agree_in_every_view():
    from labutils.data.loaders import DataNotFoundError, load_dino

    try:
        dino = load_dino()
        if dino.image_paths is None:
            raise DataNotFoundError("the dinosaur's images are missing")
    except DataNotFoundError as exc:
        pytest.skip(f"real data missing: {str(exc).splitlines()[0]}")
    idx = list(range(0, dino.n_views, 3))
    r = segment_views([dino.image(i)[::2, ::2] for i in idx], np.diag([0.5, 0.5, 1.0]) @ dino.P[idx], n=32,
                      n_check=64)
    assert r.unsure.size == 0 and r.agreement.min() >= 0.9, r.agreement


# --- the camera file and the command line --------------------------------------------------------------------------


def write_scene(folder, scene, names=None):
    names = names or [f"view{v:02d}.png" for v in range(scene.n_views)]
    for name, img in zip(names, scene.images):
        cv2.imwrite(str(folder / name), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    write_par(folder / "scene_par.txt", names, scene.K, scene.R, scene.t)
    return folder / "scene_par.txt"


def test_par_round_trip_and_errors(tmp_path, scene):
    par = write_scene(tmp_path, scene)
    v = read_par(par)
    assert np.allclose(v.P, scene.P) and v.image_paths[3] == tmp_path / "view03.png"
    lines = par.read_text().splitlines()
    cases = [
        (["x"] + lines[1:], "line 1: expected the number of images"),
        (lines[:3] + [lines[3] + " 7"] + lines[4:], "line 4: expected an image name and 21 numbers"),
        (lines[:2] + [lines[2].replace(lines[2].split()[5], "abc", 1)] + lines[3:], "line 3: 'abc' is not a number"),
        (lines[:-1], f"line 1: {scene.n_views} images announced; the file lists {scene.n_views - 1}"),
        (lines + [lines[1]], f"line {len(lines) + 1}: more lines"),
        (lines[:2] + [lines[2].replace("view01.png", "gone.png")] + lines[3:], "line 3: image gone.png not found"),
        (lines[:2] + [lines[1]] + lines[3:], "line 3: image view00.png is listed twice"),
    ]
    rot = lines[1].split()
    rot[10] = "2.0"
    cases.append((lines[:1] + [" ".join(rot)] + lines[2:], "line 2: R is not a rotation"))
    for text, message in cases:
        p = tmp_path / "bad_par.txt"
        p.write_text("\n".join(text) + "\n")
        with pytest.raises(ValueError, match=f"bad_par.txt, {message}" if message.startswith("line ")
                           else f"bad_par.txt: {message}"):
            read_par(p)


def _cli(*args, cwd):
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "labutils.carve", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, env=env)


@pytest.fixture(scope="module")
def small_scene():
    return make_snowman(10, rng=np.random.default_rng(2), image_size=(120, 90), f=150.0)


def test_cli_carves_and_writes(tmp_path, small_scene):
    par = write_scene(tmp_path, small_scene)
    (tmp_path / "masks").mkdir()
    old = os.umask(0o022)
    try:
        r = _cli(par.name, "--out", "hull.ply", "--grid", 32, "--masks", "masks", cwd=tmp_path)
    finally:
        os.umask(old)
    assert r.returncode == 0, r.stderr
    assert "carve: view 10/10" in r.stderr and "wrote hull.ply" in r.stdout
    assert validate_ply(tmp_path / "hull.ply").elements[1].name == "face"
    m = read_model(tmp_path / "hull.ply")
    assert m.normals is not None and mesh_volume(m.vertices, m.faces) > 0
    assert stat.S_IMODE(os.stat(tmp_path / "hull.ply").st_mode) == 0o644
    assert sorted(os.listdir(tmp_path / "masks"))[:2] == ["view00_mask.png", "view01_mask.png"]
    mask = cv2.imread(str(tmp_path / "masks" / "view00_mask.png"), cv2.IMREAD_GRAYSCALE) > 0
    assert mask_iou(mask, small_scene.masks[0]) > 0.97
    vol = mesh_volume(m.vertices, m.faces)
    X = VoxelGrid.from_box(small_scene.box * 1.5, 60).centres()
    hull_volume = small_scene.inside_hull(X).mean() * np.prod(small_scene.box[1] - small_scene.box[0]) * 1.5 ** 3
    assert abs(vol / hull_volume - 1) < 0.1            # a 32-voxel grid: ±1/2 voxel on a surface ~8 voxels thick


def test_cli_warns_when_the_silhouettes_do_not_match(tmp_path, small_scene):
    """Cameras shifted sideways by ±0.2 (alternately): the cones still meet, but the written model's silhouettes
    overlap the masks poorly (median IoU ~0.14); success with a warning on stderr, not a silent one."""
    par = write_scene(tmp_path, small_scene)
    lines = par.read_text().splitlines()
    for i in range(1, len(lines)):
        tok = lines[i].split()
        tok[19] = repr(float(tok[19]) + (0.2 if i % 2 else -0.2))
        lines[i] = " ".join(tok)
    par.write_text("\n".join(lines) + "\n")
    r = _cli(par.name, "--out", "hull.ply", "--grid", 24, "--threshold", 10, "--quiet", cwd=tmp_path)
    assert r.returncode == 0 and (tmp_path / "hull.ply").is_file(), r.stderr
    warning = [line for line in r.stderr.splitlines() if line.startswith("carve: warning: ")]
    assert len(warning) == 1 and "median IoU 0.1" in warning[0] and "look at --masks" in warning[0], r.stderr
    (tmp_path / "good").mkdir()
    par = write_scene(tmp_path / "good", small_scene)
    r = _cli(par.name, "--out", "hull.ply", "--grid", 24, "--threshold", 10, "--quiet", cwd=par.parent)
    assert r.returncode == 0 and "warning" not in r.stderr, r.stderr       # a good model: no warning


def test_cli_help():
    r = _cli("--help", cwd=ROOT)
    assert r.returncode == 0 and "--grid" in r.stdout and "PAR_FILE" in r.stdout


def _listing(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.mark.parametrize("case", ["missing_par", "folder_par", "bad_line", "missing_image", "broken_image", "no_folder",
                                  "no_masks_folder", "empty_carve", "bad_grid", "bad_threshold"])
def test_cli_errors(tmp_path, small_scene, case):
    par = write_scene(tmp_path, small_scene)
    args = [par.name, "--out", "hull.ply", "--grid", 24, "--threshold", 10]
    lines = par.read_text().splitlines()
    expect = None
    if case == "missing_par":
        args[0], expect = "nothing_par.txt", "nothing_par.txt: no such file"
    elif case == "folder_par":
        (tmp_path / "scene").mkdir()
        args[0], expect = "scene", "scene: is a folder"
    elif case == "bad_line":
        par.write_text("\n".join(lines[:4] + [lines[4] + " 0"] + lines[5:]) + "\n")
        expect = "scene_par.txt, line 5: expected an image name and 21 numbers"
    elif case == "missing_image":
        (tmp_path / "view03.png").unlink()
        expect = "scene_par.txt, line 5: image view03.png not found"
    elif case == "broken_image":
        (tmp_path / "view02.png").write_bytes(b"not a png")
        expect = "view02.png: cannot read the image"
    elif case == "no_folder":
        args[2], expect = "absent/hull.ply", "hull.ply: the folder absent does not exist"
    elif case == "no_masks_folder":
        args += ["--masks", "nomasks"]
        expect = "nomasks: the masks folder does not exist"
    elif case == "empty_carve":       # one camera moved sideways by the object's size: the cones no longer meet
        tok = lines[4].split()
        tok[19] = repr(float(tok[19]) + 1.0)
        par.write_text("\n".join(lines[:4] + [" ".join(tok)] + lines[5:]) + "\n")
        expect = "every voxel was carved away"
    elif case == "bad_grid":
        args[4], expect = "3", "--grid must be between 8 and 512"
    elif case == "bad_threshold":
        args[-1], expect = "blue", "--threshold must be a number or 'auto'"
    before = _listing(tmp_path)
    r = _cli(*args, "--quiet", cwd=tmp_path)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("error: ") and expect in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
    assert _listing(tmp_path) == before                 # nothing written, no temporary left
