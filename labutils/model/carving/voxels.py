"""The voxel grid, projecting voxel centres with their depth, carving them against the silhouettes (with a signed
distance field whose zero level is the hull's surface), and finding the object's box from the silhouettes alone."""
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ...core.geometry import KRt_from_P
from ...core.validation import as_array, as_matrix, as_points
from .silhouettes import _as_mask, _as_number, signed_distance_map

__all__ = ["VoxelGrid", "Carving", "project_with_depth", "inside_silhouette", "carve", "bounding_box_from_silhouettes"]


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
    def from_box(cls, box: ArrayLike, n: int) -> "VoxelGrid":
        """A grid over ``box`` ((2, 3): min and max corner) with ``n`` voxels along its longest side."""
        box = as_matrix(box, "box", (2, 3))
        size = box[1] - box[0]
        if np.any(size <= 0):
            raise ValueError(f"box must be [min corner, max corner] with max > min on every axis; got {box.tolist()}")
        n = _as_number(n, "n (voxels along the longest side)", lo=2, integer=True)
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

    def centres(self, index: ArrayLike | None = None) -> np.ndarray:
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
    P = as_array(P, name, "(V, 3, 4)")
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


def project_with_depth(P: ArrayLike, X: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
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


def inside_silhouette(X: ArrayLike, P: ArrayLike, mask: ArrayLike) -> np.ndarray:
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


def _check_masks(masks, n_views):
    masks = list(masks)
    if len(masks) != n_views:
        raise ValueError(f"masks has {len(masks)} silhouettes for {n_views} cameras: one per view")
    return [_as_mask(m, f"masks[{i}]") for i, m in enumerate(masks)]


def carve(masks: Sequence[ArrayLike], P: ArrayLike, grid: VoxelGrid, *, band_voxels: float = 2.0,
          progress: Callable[[int, int], None] | None = None) -> Carving:
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
    band_voxels = _as_number(band_voxels, "band_voxels", lo=0, open_lo=True)
    return _carve_maps([signed_distance_map(m) for m in masks], P, grid, band_voxels, progress)


def _carve_maps(D, P, grid, band_voxels=2.0, progress=None):
    """:func:`carve` from the masks' signed distance maps ``D`` (checked inputs).

    The centres lie on a grid, so ``P @ [X; 1]`` is a sum of one term per axis: three small tables per view,
    indexed by the alive voxels' (i, j, k), replace a matrix product over all of them.
    """
    t0 = time.perf_counter()
    band = float(band_voxels) * grid.voxel_size
    field = np.full(grid.n_voxels, np.inf, np.float32)
    alive = np.arange(grid.n_voxels)
    ijk = [a.astype(np.int32) for a in np.unravel_index(alive, grid.shape)]
    axes = [grid.lo[d] + (np.arange(grid.shape[d]) + 0.5) * grid.voxel_size for d in range(3)]
    for v, (Pv, Dv) in enumerate(zip(P, D)):
        if alive.size == 0:
            break
        K = KRt_from_P(Pv)[0]
        f = np.sqrt(abs(K[0, 0] * K[1, 1]))
        M = Pv[:, :3]
        tables = [np.outer(M[:, d], axes[d]) for d in range(3)]          # (3 rows u v w, n_d)
        u, vv, w = (tables[0][r][ijk[0]] + tables[1][r][ijk[1]] + tables[2][r][ijk[2]] + Pv[r, 3] for r in range(3))
        depth = np.sign(np.linalg.det(M)) * w / np.linalg.norm(M[2])
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.stack([u / w, vv / w], axis=1)
        d_px = _lookup_signed_distance(Dv, x, depth)
        d_world = np.where(depth > 0, d_px * np.maximum(depth, 0) / f, -np.inf)
        field[alive] = np.minimum(field[alive], d_world)
        keep = field[alive] > -band
        alive = alive[keep]
        ijk = [a[keep] for a in ijk]
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


def bounding_box_from_silhouettes(masks: Sequence[ArrayLike], P: ArrayLike, *, n: int = 40, margin_voxels: float = 1.5,
                                  rounds: int = 3) -> np.ndarray:
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
    n = _as_number(n, "n", lo=4, integer=True)
    margin_voxels = _as_number(margin_voxels, "margin_voxels", lo=0)
    rounds = _as_number(rounds, "rounds", lo=1, integer=True)
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
