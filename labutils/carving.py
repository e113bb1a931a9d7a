"""Space carving: silhouettes from colour, a voxel grid, carving by projection, the surface, and its overlap.

The visual hull (Laurentini 1994) is the largest shape whose projection into every view stays inside that view's
silhouette: the intersection of the silhouettes' back-projected cones. Carving it on a voxel grid (Szeliski 1993;
the dinosaur is Fitzgibbon, Cross & Zisserman's turntable sequence, SMILE 1998; Kutulakos & Seitz, "A theory of
shape by space carving", IJCV 2000, add photo-consistency) keeps a voxel when its centre projects inside every
silhouette. Here:

1. **Silhouettes from colour** (:func:`background_model`, :func:`colour_distance`, :func:`silhouette`): the
   background's colours are learnt from a thin frame at the image borders (the object does not touch it), as a set
   of cells in CIELAB with the lightness scaled down (shadows change lightness more than hue); a pixel belongs to
   the object when its colour is far from every background colour; small specks are removed and small holes filled.
2. **A voxel grid** (:class:`VoxelGrid`) over a box: given (the temple's), or found by carving a coarse grid over
   the region every camera looks at (:func:`bounding_box_from_silhouettes`).
3. **Carving** (:func:`inside_silhouette` for one view, :func:`carve` for all): vectorised over voxels, one pass
   per view over the voxels still alive. Besides the occupancy it keeps, per voxel, the smallest signed distance
   to a silhouette boundary (pixels × depth / focal length: world units), positive inside: a field whose zero level
   is the hull's surface to a fraction of a pixel, and whose sign is the occupancy.
4. **The surface** by marching cubes from scikit-image (:func:`surface_mesh`), and its **silhouettes**
   (:func:`render_silhouette`) compared with the masks by their intersection over union (:func:`mask_iou`,
   :func:`silhouette_ious`).

Pixels: ``(x, y)`` with x right, y down; pixel ``mask[r, c]`` is centred on ``(c, r)`` (OpenCV), so a point at
``(x, y)`` falls in ``mask[floor(y + 0.5), floor(x + 0.5)]``. Cameras: ``P = K [R | t]`` (any scale or sign of P
is accepted: depth is taken as in H&Z Sec. 6.2.3).
"""
import time
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ._validation import as_matrix, as_points
from .geometry import KRt_from_P

__all__ = ["BackgroundModel", "background_model", "colour_distance", "silhouette", "clean_mask", "VoxelGrid",
           "Carving", "project_with_depth", "inside_silhouette", "signed_distance_map", "carve",
           "bounding_box_from_silhouettes", "THRESHOLD_CANDIDATES", "choose_threshold", "surface_mesh", "mesh_volume",
           "render_silhouette", "mask_iou", "silhouette_ious"]


# ---------------------------------------------------------------------------------------------------------------
# Silhouettes from colour
# ---------------------------------------------------------------------------------------------------------------
def _as_image(image, name="image"):
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8:
        raise ValueError(f"{name} must be an RGB image, a (H, W, 3) uint8 array; got shape {a.shape} and dtype "
                         f"{a.dtype}")
    return a


def _as_mask(mask, name="mask", shape=None):
    a = np.asarray(mask)
    if a.ndim != 2 or (a.dtype != bool and not (a.dtype.kind in "iu" and a.size and a.max() <= 1 and a.min() >= 0)
                       and not (a.dtype.kind in "iu" and a.size == 0)):
        raise ValueError(f"{name} must be a (H, W) boolean mask; got shape {a.shape} and dtype {a.dtype}")
    if shape is not None and a.shape != tuple(shape):
        raise ValueError(f"{name} has shape {a.shape}; expected {tuple(shape)}")
    return a.astype(bool)


def _lab_cells(image, lightness_weight):
    """Each pixel's cell of the (w·L, a, b) colour grid, as a flat index into a ``(nL, 256, 256)`` array.

    OpenCV's 8-bit CIELAB stores ``L·255/100`` and ``a + 128``, ``b + 128``, already on a 1-unit grid for a and b;
    the lightness cell is ``floor(w · L)``.
    """
    import cv2

    lab = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2LAB)
    L = np.floor(lab[..., 0] * (lightness_weight * 100.0 / 255.0) + 1e-9).astype(np.int32)   # exact products: not 15.99
    return (L << 16) | (lab[..., 1].astype(np.int32) << 8) | lab[..., 2].astype(np.int32)


def _n_lightness_cells(lightness_weight):
    return int(np.floor(100 * lightness_weight)) + 1


@dataclass
class BackgroundModel:
    """The colours of the background, learnt from the image borders.

    Attributes
    ----------
    distance : (nL, 256, 256) float32 ndarray
        For each cell of the (w·L, a + 128, b + 128) colour space (1 unit wide), its distance to the nearest
        background cell.
    lightness_weight : float
        w: how much a change of lightness counts against the same change of hue (a, b).
    n_samples : int
        Border pixels the model was learnt from.
    """

    distance: np.ndarray
    lightness_weight: float
    n_samples: int


def _border_pixels(image, border_px):
    b = border_px
    return np.concatenate([image[:b].ravel(), image[-b:].ravel(), image[b:-b, :b].ravel(), image[b:-b, -b:].ravel()])


def background_model(images, *, border_px=4, lightness_weight=0.3, min_count=3):
    """Learn the background's colours from a frame ``border_px`` wide around every image.

    The colours seen there (in CIELAB, lightness scaled by ``lightness_weight``) mark cells of a 1-unit grid; a
    cell counts as background when at least ``min_count`` border pixels fall in it or its 26 neighbours (so a few
    stray object pixels at the border do not count). A Euclidean distance transform of that set gives, for every
    colour, its distance to the nearest background colour.

    Parameters
    ----------
    images : sequence of (H, W, 3) uint8 RGB images
    border_px : int
        Width of the frame, pixels: the object must not reach into it.
    lightness_weight : float
        In (0, 1]: 1 is plain CIELAB; smaller values forgive shading and shadows on the background.
    min_count : int

    Returns
    -------
    BackgroundModel

    Examples
    --------
    >>> img = np.zeros((40, 40, 3), np.uint8); img[...] = (40, 60, 200); img[15:25, 15:25] = (230, 120, 20)
    >>> m = background_model([img])
    >>> d = colour_distance(img, m)
    >>> bool(d[20, 20] > 50), float(d[0, 0])
    (True, 0.0)
    """
    if not 0 < lightness_weight <= 1:
        raise ValueError(f"lightness_weight must be in (0, 1]; got {lightness_weight}")
    images = list(images)
    if not images:
        raise ValueError("images is empty: the background is learnt from at least one image")
    samples = []
    for i, img in enumerate(images):
        img = _as_image(img, f"images[{i}]")
        if min(img.shape[:2]) <= 2 * border_px:
            raise ValueError(f"images[{i}] ({img.shape[1]}x{img.shape[0]}) is too small for a {border_px}-pixel border")
        samples.append(_border_pixels(_lab_cells(img, lightness_weight), border_px))
    X = np.concatenate(samples)
    nL = _n_lightness_cells(lightness_weight)
    counts = np.bincount(X, minlength=nL * 256 * 256)
    counts = ndimage.uniform_filter(counts.reshape(nL, 256, 256).astype(np.float32), 3, mode="constant") * 27
    occupied = counts >= min_count - 1e-3
    if not occupied.any():
        raise ValueError(f"no colour is seen {min_count} times at the image borders: lower min_count")
    dist = ndimage.distance_transform_edt(~occupied).astype(np.float32)
    return BackgroundModel(dist, float(lightness_weight), int(len(X)))


def colour_distance(image, model):
    """Distance (CIELAB units, lightness weighted) of each pixel's colour to the nearest background colour.

    Parameters
    ----------
    image : (H, W, 3) uint8 RGB
    model : BackgroundModel

    Returns
    -------
    (H, W) float32 ndarray
        0 on colours seen at the borders; large on the object.
    """
    return model.distance.ravel()[_lab_cells(_as_image(image), model.lightness_weight)]


def clean_mask(mask, *, min_component=0.02, max_hole=0.002):
    """Remove small specks and fill small holes of a silhouette.

    Parameters
    ----------
    mask : (H, W) bool
    min_component : float
        Connected parts (8-connected) smaller than this fraction of the largest part are removed.
    max_hole : float
        Holes (4-connected background regions that do not touch the image border) smaller than this fraction of
        the object's area are filled; larger ones (between the temple's columns) stay.

    Returns
    -------
    (H, W) bool ndarray

    Examples
    --------
    >>> m = np.zeros((30, 30), bool); m[5:25, 5:25] = True; m[10, 10] = False; m[1, 1] = True
    >>> c = clean_mask(m, max_hole=0.01)       # a 1-pixel hole in a 400-pixel object: filled; the speck: removed
    >>> bool(c[10, 10]), bool(c[1, 1]), int(c.sum())
    (True, False, 400)
    """
    import cv2

    mask = _as_mask(mask)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if n <= 1:
        return mask.copy()
    areas = stats[1:, cv2.CC_STAT_AREA]
    keep = np.zeros(n, bool)
    keep[1:] = areas >= min_component * areas.max()
    out = keep[lab]
    n, lab, stats, _ = cv2.connectedComponentsWithStats((~out).astype(np.uint8), connectivity=4)
    border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    fill = stats[:, cv2.CC_STAT_AREA] < max_hole * out.sum()
    fill[border] = False
    fill[0] = False                                                   # label 0 is the object itself
    return out | (fill[lab] & ~out)


def silhouette(image, model, *, threshold=2.5, min_component=0.02, max_hole=0.002):
    """The object's silhouette: pixels whose colour is farther than ``threshold`` from every background colour.

    Parameters
    ----------
    image : (H, W, 3) uint8 RGB
    model : BackgroundModel
        From :func:`background_model`.
    threshold : float
        CIELAB units (lightness weighted); the background's own colours are at distance 0.
    min_component, max_hole : float
        See :func:`clean_mask`.

    Returns
    -------
    (H, W) bool ndarray
    """
    return clean_mask(colour_distance(image, model) > threshold, min_component=min_component, max_hole=max_hole)


# ---------------------------------------------------------------------------------------------------------------
# The voxel grid and carving
# ---------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class VoxelGrid:
    """A regular grid of cubic voxels over a box.

    Voxel ``(i, j, k)`` is centred on ``lo + (i + ½, j + ½, k + ½) · voxel_size``; arrays over the grid have shape
    ``shape`` and flat indices in C order.

    Attributes
    ----------
    lo : (3,) ndarray
        The box's min corner (world).
    voxel_size : float
    shape : (3,) tuple of int

    Examples
    --------
    >>> g = VoxelGrid.from_box([[0, 0, 0], [2, 1, 0.5]], 4)
    >>> g.shape, g.voxel_size, g.centres()[0].tolist()
    ((4, 2, 1), 0.5, [0.25, 0.25, 0.25])
    """

    lo: np.ndarray
    voxel_size: float
    shape: tuple

    @classmethod
    def from_box(cls, box, n):
        """A grid over ``box`` ((2, 3): min and max corner) with ``n`` voxels along its longest side."""
        box = as_matrix(box, "box", (2, 3))
        size = box[1] - box[0]
        if np.any(size <= 0):
            raise ValueError(f"box must be [min corner, max corner] with max > min on every axis; got {box.tolist()}")
        if int(n) != n or n < 2:
            raise ValueError(f"n (voxels along the longest side) must be an integer >= 2; got {n}")
        s = float(size.max() / n)
        shape = tuple(int(v) for v in np.maximum(np.ceil(size / s - 1e-9), 1))
        centre = box.mean(axis=0)
        lo = centre - 0.5 * s * np.array(shape)
        return cls(lo, s, shape)

    @property
    def n_voxels(self):
        return int(np.prod(self.shape))

    @property
    def box(self):
        """(2, 3): the grid's min and max corner."""
        return np.array([self.lo, self.lo + self.voxel_size * np.array(self.shape)])

    def centres(self, index=None):
        """World coordinates of voxel centres: all ``(n_voxels, 3)`` in C order, or those of flat ``index``."""
        index = np.arange(self.n_voxels) if index is None else np.asarray(index)
        ijk = np.stack(np.unravel_index(index, self.shape), axis=-1)
        return self.lo + (ijk + 0.5) * self.voxel_size


@dataclass
class Carving:
    """What :func:`carve` returns.

    Attributes
    ----------
    grid : VoxelGrid
    occupied : (nx, ny, nz) bool ndarray
        Voxels whose centre projects inside every silhouette (in front of every camera).
    field : (nx, ny, nz) float32 ndarray
        Smallest signed distance to a silhouette boundary over the views, in world units (pixels × depth / focal
        length), positive inside, clipped below at ``-band``: ``occupied == (field > 0)``.
    band : float
        Voxels farther than this outside were dropped early (world units; 2 voxels).
    seconds : float
        Time spent carving.
    """

    grid: VoxelGrid
    occupied: np.ndarray
    field: np.ndarray
    band: float
    seconds: float = 0.0

    @property
    def n_occupied(self):
        return int(self.occupied.sum())


def _as_cameras(P, name="P"):
    P = np.asarray(P, dtype=float)
    if P.ndim == 2:
        P = P[None]
    if P.ndim != 3 or P.shape[1:] != (3, 4):
        raise ValueError(f"{name} must be a (V, 3, 4) stack of camera matrices; got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ValueError(f"{name} has non-finite entries (NaN or inf)")
    det = np.linalg.det(P[:, :, :3])
    bad = np.abs(det) <= 1e-12 * np.abs(P[:, :, :3]).max(axis=(1, 2)) ** 3
    if bad.any():
        raise ValueError(f"{name}[{int(np.flatnonzero(bad)[0])}] has a singular left 3x3 block: not a finite camera")
    return P


def project_with_depth(P, X):
    """Pixels and depths of world points ``X`` (N, 3) in camera ``P`` (3, 4) (H&Z Sec. 6.2.3).

    The depth is ``sign(det M) w / ‖m³‖`` (M the left 3×3 block of P, m³ its third row, w the third coordinate
    of ``P X_h``): the distance along the principal axis, positive in front, whatever P's scale and sign.

    Returns
    -------
    x : (N, 2) ndarray
        Pixels (NaN where the depth is 0).
    depth : (N,) ndarray

    Examples
    --------
    >>> P = np.hstack([np.eye(3), [[0.], [0.], [2.]]])
    >>> x, d = project_with_depth(-3 * P, [[1., 2., 2.]])
    >>> x.tolist(), d.tolist()
    ([[0.25, 0.5]], [4.0])
    """
    P = as_matrix(P, "P", (3, 4))
    X = as_points(X, "X", dim=3, min_n=0)
    M = P[:, :3]
    det = np.linalg.det(M)
    if abs(det) <= 1e-12 * np.abs(M).max() ** 3:
        raise ValueError("P has a singular left 3x3 block: it is not a finite projective camera")
    x_h = X @ P[:, :3].T + P[:, 3]
    w = x_h[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = x_h[:, :2] / np.where(w == 0, np.nan, w)[:, None]
    return x, np.sign(det) * w / np.linalg.norm(M[2])


def _project_fast(P, X):
    """:func:`project_with_depth` without the checks, for the carving loops (P checked by the caller)."""
    M = P[:, :3]
    x_h = X @ M.T + P[:, 3]
    w = x_h[:, 2]
    depth = np.sign(np.linalg.det(M)) * w / np.linalg.norm(M[2])
    with np.errstate(divide="ignore", invalid="ignore"):
        x = x_h[:, :2] / w[:, None]
    return x, depth


def inside_silhouette(X, P, mask):
    """The carving test of one view: which points project inside the silhouette (nearest pixel), in front.

    Parameters
    ----------
    X : (N, 3) array_like
        World points (voxel centres).
    P : (3, 4) array_like
        The camera.
    mask : (H, W) bool
        The silhouette.

    Returns
    -------
    (N,) bool ndarray
        True where the point is in front of the camera (depth > 0) and lands on a mask pixel; a point that
        projects outside the image is outside the silhouette.

    Examples
    --------
    >>> P = np.hstack([np.eye(3), [[0.], [0.], [1.]]])         # K = I: pixel = (X/Z', Y/Z') with Z' = Z + 1
    >>> mask = np.zeros((3, 4), bool); mask[2, 1] = True      # row 2, column 1: the pixel centred on (1, 2)
    >>> inside_silhouette([[1., 2., 0.], [2., 1., 0.], [-1., -2., -2.]], P, mask).tolist()
    [True, False, False]
    """
    mask = _as_mask(mask)
    x, depth = project_with_depth(P, X)
    h, w = mask.shape
    ok = depth > 0
    c = np.floor(np.where(ok, x[:, 0], -1.0) + 0.5)
    r = np.floor(np.where(ok, x[:, 1], -1.0) + 0.5)
    ok &= (c >= 0) & (c < w) & (r >= 0) & (r < h)
    out = np.zeros(len(depth), bool)
    out[ok] = mask[r[ok].astype(np.int64), c[ok].astype(np.int64)]
    return out


def signed_distance_map(mask):
    """Signed distance of each pixel to the silhouette's boundary, pixels: positive inside, negative outside.

    Pixels next to the boundary get ±½ (the boundary runs between pixel centres); outside the image counts
    as outside the silhouette.

    Examples
    --------
    >>> m = np.zeros((9, 9), bool); m[2:7, 2:7] = True
    >>> signed_distance_map(m)[4].tolist()
    [-1.5, -0.5, 0.5, 1.5, 2.5, 1.5, 0.5, -0.5, -1.5]
    """
    import cv2

    mask = _as_mask(mask)
    pad = np.pad(mask, 1).astype(np.uint8)
    d_in = cv2.distanceTransform(pad, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
    d_out = cv2.distanceTransform(1 - pad, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
    return np.where(mask, d_in - 0.5, 0.5 - d_out).astype(np.float32)


def _check_masks(masks, n_views):
    masks = list(masks)
    if len(masks) != n_views:
        raise ValueError(f"masks has {len(masks)} silhouettes for {n_views} cameras: one per view")
    return [_as_mask(m, f"masks[{i}]") for i, m in enumerate(masks)]


def carve(masks, P, grid, *, band_voxels=2.0, progress=None):
    """Carve the visual hull: keep the voxels whose centre projects inside every silhouette.

    One pass per view over the voxels still alive (vectorised); a voxel farther than ``band_voxels`` outside a
    silhouette's cone is dropped, which makes the later passes cheaper.

    Parameters
    ----------
    masks : sequence of (H, W) bool
        One silhouette per view (sizes may differ between views).
    P : (V, 3, 4) array_like
        The cameras, ``P = K [R | t]``.
    grid : VoxelGrid
    band_voxels : float
        Width of the band kept around the surface in the distance field, voxels (≥ √3 keeps the field exact where
        marching cubes reads it).
    progress : callable, optional
        Called as ``progress(view, n_alive)`` after each view (e.g. to print to stderr).

    Returns
    -------
    Carving

    Raises
    ------
    ValueError
        If the masks and cameras do not pair up, a mask is not boolean, or a camera is not finite.

    Examples
    --------
    >>> K = np.array([[10., 0, 20], [0, 10, 20], [0, 0, 1]])
    >>> P = K @ np.hstack([np.eye(3), [[0.], [0.], [5.]]])           # a camera 5 units from the origin
    >>> mask = np.zeros((40, 40), bool); mask[15:25, 15:25] = True   # sees a square of 10x10 pixels
    >>> c = carve([mask], P[None], VoxelGrid.from_box([[-2, -2, -2], [2, 2, 2]], 8))
    >>> c.occupied.shape, bool(np.array_equal(c.occupied, c.field > 0)), c.n_occupied > 0
    ((8, 8, 8), True, True)
    """
    P = _as_cameras(P)
    masks = _check_masks(masks, len(P))
    if not isinstance(grid, VoxelGrid):
        raise ValueError(f"grid must be a VoxelGrid; got {type(grid).__name__}")
    return _carve_maps([signed_distance_map(m) for m in masks], P, grid, band_voxels, progress)


def _carve_maps(D, P, grid, band_voxels=2.0, progress=None):
    """:func:`carve` from the masks' signed distance maps ``D`` (checked inputs)."""
    t0 = time.perf_counter()
    band = float(band_voxels) * grid.voxel_size
    field = np.full(grid.n_voxels, np.inf, np.float32)
    alive = np.arange(grid.n_voxels)
    X = grid.centres()
    for v, (Pv, Dv) in enumerate(zip(P, D)):
        if alive.size == 0:
            break
        K = KRt_from_P(Pv)[0]
        f = np.sqrt(abs(K[0, 0] * K[1, 1]))
        x, depth = _project_fast(Pv, X[alive])
        d_px = _lookup_signed_distance(Dv, x, depth)
        d_world = np.where(depth > 0, d_px * np.maximum(depth, 0) / f, -np.inf)
        field[alive] = np.minimum(field[alive], d_world)
        alive = alive[field[alive] > -band]
        if progress is not None:
            progress(v, int(alive.size))
    field = np.maximum(field, -band).reshape(grid.shape)
    return Carving(grid, field > 0, field.astype(np.float32), band, time.perf_counter() - t0)


def _lookup_signed_distance(D, x, depth):
    """D at the nearest pixel; outside the image, the value at the nearest border pixel (at most -½) minus the
    distance to it; behind the camera, -inf."""
    h, w = D.shape
    ok = depth > 0
    xx = np.where(ok, x[:, 0], 0.0)
    yy = np.where(ok, x[:, 1], 0.0)
    c = np.floor(xx + 0.5)
    r = np.floor(yy + 0.5)
    cc = np.clip(c, 0, w - 1)
    rr = np.clip(r, 0, h - 1)
    val = D[rr.astype(np.int64), cc.astype(np.int64)].astype(float)
    out_img = (c != cc) | (r != rr)
    if out_img.any():
        gap = np.hypot(xx - cc, yy - rr)
        val = np.where(out_img, np.minimum(val, -0.5) - gap, val)
    return np.where(ok, val, -np.inf)


def _camera_centre(Pv):
    M = Pv[:, :3]
    return -np.linalg.solve(M, Pv[:, 3])


def _closest_point_to_rays(C, d):
    """The point nearest (least squares) to the lines ``C[i] + s d[i]``; None if they are (nearly) parallel."""
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    Q = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    A, b = Q.sum(axis=0), np.einsum("vij,vj->i", Q, C)
    if np.linalg.cond(A) > 1e8:
        return None
    return np.linalg.solve(A, b)


def bounding_box_from_silhouettes(masks, P, *, n=40, margin_voxels=1.5, rounds=3):
    """The box around the visual hull, found from the silhouettes and cameras alone.

    1. The rays through the silhouettes' centroids meet (in the least-squares sense) near the object: X0.
    2. A cube around X0 as wide as the largest silhouette's bounding rectangle back-projected to X0's depth
       (times 1.5) holds the hull.
    3. Carve that cube on a coarse grid (``n`` voxels along its longest side), keep the voxels whose cube may reach
       inside every cone (field > -√3/2 voxel), and take their box plus ``margin_voxels``; repeat on that box
       ``rounds`` times (each round is finer). A box that touches its search region is doubled and searched again.

    Parameters
    ----------
    masks : sequence of (H, W) bool
    P : (V, 3, 4) array_like
    n : int
        Voxels along the longest side in each coarse round.

    Returns
    -------
    (2, 3) ndarray
        Min and max corner.

    Raises
    ------
    ValueError
        If a silhouette is empty, the centroid rays are (nearly) parallel, or nothing survives the carving (the
        masks and cameras disagree).
    """
    P = _as_cameras(P)
    masks = _check_masks(masks, len(P))
    C = np.array([_camera_centre(Pv) for Pv in P])
    rays, rects = [], []
    for v, (Pv, mask) in enumerate(zip(P, masks)):
        ys, xs = np.nonzero(mask)
        if xs.size == 0:
            raise ValueError(f"masks[{v}] is empty: every voxel would be carved away (the object is not seen)")
        rays.append(np.linalg.solve(Pv[:, :3], [xs.mean(), ys.mean(), 1.0]))
        rects.append([xs.min() - 0.5, ys.min() - 0.5, xs.max() + 0.5, ys.max() + 0.5])
    X0 = _closest_point_to_rays(C, np.array(rays))
    if X0 is None:
        raise ValueError("the rays through the silhouettes' centres are (nearly) parallel: the cameras do not look "
                         "at one object from different directions, so carving cannot bound it")
    radius = 0.0
    for Pv, (x0, y0, x1, y1), Cv in zip(P, rects, C):
        _, depth = project_with_depth(Pv, X0[None])
        corners = np.linalg.solve(Pv[:, :3], np.array([[x0, y0, 1], [x1, y0, 1], [x0, y1, 1], [x1, y1, 1.0]]).T).T
        _, dc = project_with_depth(Pv, Cv + corners)                 # depth of one step along each corner ray
        pts = Cv + corners * (abs(depth[0]) / np.abs(dc))[:, None]
        radius = max(radius, np.linalg.norm(pts - X0, axis=1).max())
    box = np.array([X0 - 1.5 * radius, X0 + 1.5 * radius])
    D = [signed_distance_map(m) for m in masks]
    for _ in range(rounds + 4):
        grid = VoxelGrid.from_box(box, n)
        c = _carve_maps(D, P, grid)
        keep = c.field > -0.87 * grid.voxel_size
        if not keep.any():
            raise ValueError("every voxel was carved away while looking for the object's box: the masks and "
                             "cameras disagree (check the cameras' convention P = K [R | t] and the silhouettes)")
        ijk = np.argwhere(keep)
        if np.any(ijk.min(axis=0) == 0) or np.any(ijk.max(axis=0) == np.array(grid.shape) - 1):
            centre, half = box.mean(axis=0), box[1] - box.mean(axis=0)
            box = np.array([centre - 2 * half, centre + 2 * half])          # touches the region: look wider
            continue
        new = np.array([grid.lo + (ijk.min(axis=0) + 0.5 - margin_voxels) * grid.voxel_size,
                        grid.lo + (ijk.max(axis=0) + 0.5 + margin_voxels) * grid.voxel_size])
        rounds -= 1
        if rounds <= 0 or np.allclose(new, box, rtol=0, atol=0.5 * grid.voxel_size):
            return new
        box = new
    raise ValueError("the carved region keeps touching the search region: the silhouettes do not bound the object "
                     "(does it reach the image border in every view?)")


THRESHOLD_CANDIDATES = (0.5, 1.5, 2.5, 3.5, 5.0)
"""Colour thresholds tried by :func:`choose_threshold` (CIELAB units, lightness weighted)."""


def choose_threshold(distances, P, *, candidates=THRESHOLD_CANDIDATES, n=40, every=1, min_component=0.02,
                     max_hole=0.002):
    """Pick the colour threshold whose silhouettes agree best with each other (no ground truth needed).

    With exact cameras, the visual hull of perfect silhouettes reprojects exactly onto each of them; a mask that
    misses part of the object carves it away in every other view, and one with extra background is carved away
    by the others. So for each candidate threshold we carve a coarse grid (``n`` voxels along the box's longest
    side), take its surface and score the silhouettes' agreement: the median over views of the IoU between the
    surface's silhouette and the mask. The best-scoring threshold wins.

    Parameters
    ----------
    distances : sequence of (H, W) float arrays
        :func:`colour_distance` of each view.
    P : (V, 3, 4) array_like
    candidates : sequence of float
    n : int
    every : int
        Score every ``every``-th view only (all views are carved).

    Returns
    -------
    best : float
    scores : (len(candidates), 2) ndarray
        Per candidate: the median and the minimum IoU over the views scored.

    Raises
    ------
    ValueError
        If no candidate leaves a non-empty carving.
    """
    P = _as_cameras(P)
    distances = list(distances)
    if len(distances) != len(P):
        raise ValueError(f"distances has {len(distances)} maps for {len(P)} cameras: one per view")
    candidates = sorted(float(c) for c in candidates)
    masks_of = {c: [clean_mask(d > c, min_component=min_component, max_hole=max_hole) for d in distances]
                for c in candidates}
    box = bounding_box_from_silhouettes(masks_of[candidates[0]], P)    # the most inclusive masks: the largest box
    grid = VoxelGrid.from_box(box, n)
    scores = np.full((len(candidates), 2), -1.0)
    for k, c in enumerate(candidates):
        masks = masks_of[c]
        carving = _carve_maps([signed_distance_map(m) for m in masks], P, grid)
        if not carving.occupied.any():
            continue
        V, F, _ = surface_mesh(carving)
        ious = silhouette_ious(V, F, masks[::every], P[::every])
        scores[k] = np.median(ious), ious.min()
    if np.all(scores[:, 0] < 0):
        raise ValueError("every candidate threshold carves every voxel away: the masks and cameras disagree")
    return candidates[int(np.argmax(scores[:, 0]))], scores


# ---------------------------------------------------------------------------------------------------------------
# The surface, its silhouettes, and their overlap with the masks
# ---------------------------------------------------------------------------------------------------------------
def surface_mesh(carving, *, level=0.0, step_size=1):
    """The carved volume's surface by marching cubes (scikit-image; Lorensen & Cline 1987; Lewiner et al. 2003).

    The field is padded by one voxel of "outside" on every side, so the surface is closed even where the hull
    touches the grid's border.

    Parameters
    ----------
    carving : Carving
    level : float
        The iso-level of ``carving.field`` (world units; 0 is the silhouettes' boundary).
    step_size : int
        Marching cubes' step, voxels (2 gives a coarser mesh, about a quarter of the triangles).

    Returns
    -------
    vertices : (N, 3) ndarray
        World coordinates.
    faces : (F, 3) int ndarray
        Triangles, counter-clockwise seen from outside (normals out).
    normals : (N, 3) ndarray
        Unit outward normals at the vertices.

    Raises
    ------
    ValueError
        If nothing is occupied (every voxel was carved away).
    """
    from skimage.measure import marching_cubes

    if not carving.occupied.any():
        raise ValueError("every voxel was carved away: there is no surface (the masks or cameras disagree)")
    f = np.pad(carving.field, 1, constant_values=-carving.band)
    s = carving.grid.voxel_size
    verts, faces, normals, _ = marching_cubes(f, level=level, spacing=(s, s, s), step_size=step_size,
                                              allow_degenerate=False)
    verts = verts + carving.grid.lo - 0.5 * s                         # index 1 of the padded field is voxel 0
    # scikit-image orders the corners so that the normals (toward lower values: outward here) follow the left-hand
    # rule; flip to counter-clockwise seen from outside, the usual convention (PLY viewers, signed volume > 0)
    faces = faces[:, ::-1].astype(np.int64)
    return verts, faces, normals


def mesh_volume(vertices, faces):
    """Signed volume of a closed triangle mesh (positive when the faces are counter-clockwise seen from outside).

    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> round(mesh_volume(V, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])), 6)
    0.166667
    """
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def render_silhouette(vertices, faces, P, image_size):
    """The silhouette of a triangle mesh in a view: the pixels whose centre falls in a projected triangle.

    Vectorised scan conversion: for every (triangle, pixel row) pair the row's span inside the triangle is found
    from the three edges at once; the spans are accumulated as +1 at their start and -1 after their end, and a
    running sum along each row marks the pixels that some span covers.

    Parameters
    ----------
    vertices : (N, 3) array_like
    faces : (F, 3) int array_like
    P : (3, 4) array_like
    image_size : (width, height)

    Returns
    -------
    (height, width) bool ndarray

    Raises
    ------
    ValueError
        If a vertex of a face is at or behind the camera's plane (its projection is not bounded).

    Examples
    --------
    >>> P = np.hstack([np.eye(3), [[0.], [0.], [1.]]])
    >>> V = np.array([[0., 0, 0], [3, 0, 0], [0, 3, 0]])
    >>> render_silhouette(V, [[0, 1, 2]], P, (4, 3)).astype(int)
    array([[1, 1, 1, 1],
           [1, 1, 1, 0],
           [1, 1, 0, 0]])
    """
    V = as_points(vertices, "vertices", dim=3)
    F = np.asarray(faces)
    if F.ndim != 2 or F.shape[1] != 3 or (F.size and F.dtype.kind not in "iu"):
        raise ValueError(f"faces must be an (F, 3) integer array of triangles; got shape {F.shape}, dtype {F.dtype}")
    if F.size and (F.min() < 0 or F.max() >= len(V)):
        raise ValueError(f"faces hold vertex indices 0..{len(V) - 1}; got {int(F.min())}..{int(F.max())}")
    w, h = (int(v) for v in image_size)
    if F.size == 0:
        return np.zeros((h, w), bool)
    x, depth = project_with_depth(P, V)
    if np.any(depth[F] <= 0):
        raise ValueError("the mesh reaches behind the camera: its silhouette is unbounded")
    return _fill_triangles(x[F], h, w)


def _fill_triangles(tri, h, w, eps=1e-9):
    """Union of the triangles ``tri`` (T, 3, 2) as a (h, w) mask of the pixel centres they contain."""
    y = tri[..., 1]
    r0 = np.maximum(np.ceil(y.min(axis=1) - eps), 0).astype(np.int64)
    r1 = np.minimum(np.floor(y.max(axis=1) + eps), h - 1).astype(np.int64)
    n_rows = np.maximum(r1 - r0 + 1, 0)
    k = np.repeat(np.arange(len(tri)), n_rows)                       # one entry per (triangle, row)
    row = r0[k] + np.arange(k.size) - np.repeat(np.cumsum(n_rows) - n_rows, n_rows)
    xl = np.full(k.size, np.inf)
    xr = np.full(k.size, -np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        p, q = tri[k, i], tri[k, j]
        lo, hi = np.minimum(p[:, 1], q[:, 1]), np.maximum(p[:, 1], q[:, 1])
        hit = (row >= lo - eps) & (row <= hi + eps)
        dy = q[:, 1] - p[:, 1]
        flat = np.abs(dy) < eps
        with np.errstate(divide="ignore", invalid="ignore"):
            xs = np.where(flat, p[:, 0], p[:, 0] + (row - p[:, 1]) * (q[:, 0] - p[:, 0]) / np.where(flat, 1.0, dy))
        x_lo = np.where(flat, np.minimum(p[:, 0], q[:, 0]), xs)
        x_hi = np.where(flat, np.maximum(p[:, 0], q[:, 0]), xs)
        xl = np.where(hit, np.minimum(xl, x_lo), xl)
        xr = np.where(hit, np.maximum(xr, x_hi), xr)
    c0 = np.maximum(np.ceil(xl - eps), 0)
    c1 = np.minimum(np.floor(xr + eps), w - 1)
    ok = np.isfinite(c0) & np.isfinite(c1) & (c1 >= c0)
    c0, c1, row = c0[ok].astype(np.int64), c1[ok].astype(np.int64), row[ok]
    # each span [c0, c1] of a row: +1 at c0, -1 after c1; a running sum along the row counts the spans covering a pixel
    n = h * (w + 1)
    cover = np.bincount(row * (w + 1) + c0, minlength=n) - np.bincount(row * (w + 1) + c1 + 1, minlength=n)
    return np.cumsum(cover.reshape(h, w + 1), axis=1)[:, :w] > 0


def mask_iou(a, b):
    """Intersection over union of two masks: ``|a ∧ b| / |a ∨ b|``, in [0, 1].

    Raises
    ------
    ValueError
        If the shapes differ, or both masks are empty (the IoU is undefined).

    Examples
    --------
    >>> a = np.zeros((2, 4), bool); a[:, :2] = True
    >>> b = np.zeros((2, 4), bool); b[:, 1:3] = True
    >>> mask_iou(a, b)
    0.3333333333333333
    """
    a = _as_mask(a, "a")
    b = _as_mask(b, "b", shape=a.shape)
    union = np.count_nonzero(a | b)
    if union == 0:
        raise ValueError("both masks are empty: their IoU is undefined")
    return float(np.count_nonzero(a & b) / union)


def silhouette_ious(vertices, faces, masks, P):
    """Per view: the IoU of the mesh's silhouette (:func:`render_silhouette`) with that view's mask.

    Returns
    -------
    (V,) ndarray
    """
    P = _as_cameras(P)
    masks = _check_masks(masks, len(P))
    return np.array([mask_iou(render_silhouette(vertices, faces, Pv, m.shape[::-1]), m) for Pv, m in zip(P, masks)])
