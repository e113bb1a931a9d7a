"""Fusing the depth maps of several pairs into one point cloud: keep what other views confirm, merge duplicates.

Each depth map is noisy and has its own mistakes (a mismatch that passed the left–right check, a stretch of
background). A point that is really on the surface is seen, at the same depth, by the other depth maps whose cameras
see that part of the surface; a mistake is not. So every point of every map is projected into the other maps, and it
is kept when at least ``min_agree`` of them hold a depth within a relative tolerance of the point's own depth there
(the consistency test of Merrell et al., "Real-time visibility-based fusion of depth maps", ICCV 2007, in its
simplest form; Furukawa & Hernández, *Multi-View Stereo: A Tutorial*, 2015, Sec. 4.1). A map that sees something
nearer along the ray (the point is hidden there) or nothing at all neither confirms nor rejects.

The map's depth where a point projects is interpolated between its four pixels (bilinearly in inverse depth, exact
on a plane), so that a steep surface, whose depth changes a lot from one pixel to the next, is not rejected for the
pixel grid's sake.

The surviving points of overlapping maps describe the same surface several times; they are **merged** on a voxel
grid (points in one cell are averaged, position and colour), which also evens out the density.

Conventions: world points are rows ``(N, 3)``; depth maps are :class:`labutils.model.DepthMap`; a point's pixel
in a map is the nearest pixel centre, ``(floor(x + ½), floor(y + ½))``.
"""
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ...core.validation import as_points, as_positive
from .depth import DepthMap

__all__ = ["FusedCloud", "depth_in_map", "depth_agreement", "merge_points", "fuse_depth_maps"]


def _as_maps(depth_maps, name="depth_maps", min_n=1):
    maps = list(depth_maps) if isinstance(depth_maps, (list, tuple)) else None
    if maps is None or len(maps) < min_n or not all(isinstance(m, DepthMap) for m in maps):
        raise ValueError(f"{name} must be a list of at least {min_n} DepthMap; got {depth_maps!r:.80}")
    return maps


def depth_in_map(X: ArrayLike, depth_map: DepthMap) -> tuple[np.ndarray, np.ndarray]:
    """Each point's depth in a map's camera, and the map's depth where the point projects.

    The map's depth there is interpolated from the four pixels around the point, bilinearly in **inverse** depth
    (``1/Z`` is an affine function of the pixel on a plane, so a plane is interpolated exactly, even seen at a
    grazing angle, where the depth changes a lot from one pixel to the next); where one of the four has no depth,
    the nearest pixel's depth is taken.

    Returns
    -------
    z : (N,) ndarray
        Depth of each point along the camera's z axis.
    z_map : (N,) ndarray
        The map's depth at the point's pixel; NaN where the point is behind the camera, projects outside the map, or
        the map has no depth at its nearest pixel.

    Examples
    --------
    >>> K = np.array([[10.0, 0, 2.5], [0, 10, 1.5], [0, 0, 1]])
    >>> dm = DepthMap(np.full((4, 6), 2.0), K, np.eye(3), np.zeros(3))
    >>> z, z_map = depth_in_map([[0.0, 0.0, 2.1], [5.0, 0.0, 1.0]], dm)
    >>> z.tolist(), z_map.tolist()
    ([2.1, 1.0], [2.0, nan])
    >>> plane = DepthMap(1 / (0.5 + 0.01 * np.arange(6)) * np.ones((4, 1)), K, np.eye(3), np.zeros(3))
    >>> float(depth_in_map([[0.0, 0.0, 1.0]], plane)[1][0] * (0.5 + 0.01 * 2.5))      # between pixels, exactly
    1.0
    """
    X = as_points(X, "X", dim=3, min_n=0)
    if not isinstance(depth_map, DepthMap):
        raise ValueError(f"depth_map must be a DepthMap; got {type(depth_map).__name__}")
    xc = X @ depth_map.R.T + depth_map.t
    z = xc[:, 2]
    h, w = depth_map.shape
    z_map = np.full(len(X), np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = xc @ depth_map.K.T
        x, y = u[:, 0] / u[:, 2], u[:, 1] / u[:, 2]
        col, row = np.floor(x + 0.5), np.floor(y + 0.5)
    ok = (z > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
    z_map[ok] = depth_map.depth[row[ok].astype(int), col[ok].astype(int)]
    # bilinear in 1/Z where the four pixels around the point all have a depth
    x0, y0 = np.floor(x), np.floor(y)
    inner = ok & (x0 >= 0) & (x0 < w - 1) & (y0 >= 0) & (y0 < h - 1)
    c0, r0 = x0[inner].astype(int), y0[inner].astype(int)
    fx, fy = (x - x0)[inner], (y - y0)[inner]
    D = depth_map.depth
    corners = np.stack([D[r0, c0], D[r0, c0 + 1], D[r0 + 1, c0], D[r0 + 1, c0 + 1]])
    weights = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy])
    full = np.all(np.isfinite(corners), axis=0)
    inv = np.sum(weights[:, full] / corners[:, full], axis=0)
    idx = np.flatnonzero(inner)[full]
    z_map[idx] = 1.0 / inv
    return z, z_map


def depth_agreement(X: ArrayLike, depth_maps: Sequence[DepthMap], rel_tol: float = 0.01) -> np.ndarray:
    """How many of ``depth_maps`` confirm each point: ``|z - z_map| <= rel_tol · z_map`` where it projects
    (:func:`depth_in_map`).

    Returns
    -------
    (N,) int ndarray

    Examples
    --------
    >>> K = np.array([[10.0, 0, 2.5], [0, 10, 1.5], [0, 0, 1]])
    >>> maps = [DepthMap(np.full((4, 6), z), K, np.eye(3), np.zeros(3)) for z in (2.0, 2.01, 3.0)]
    >>> depth_agreement([[0.0, 0.0, 2.0], [0.0, 0.0, 3.0]], maps).tolist()
    [2, 1]
    """
    maps = _as_maps(depth_maps)
    rel_tol = as_positive(rel_tol, "rel_tol")
    X = as_points(X, "X", dim=3, min_n=0)
    count = np.zeros(len(X), int)
    for m in maps:
        z, z_map = depth_in_map(X, m)
        with np.errstate(invalid="ignore"):
            count += np.abs(z - z_map) <= rel_tol * z_map
    return count


def merge_points(X: ArrayLike, voxel_size: float, colors: ArrayLike | None = None) -> tuple:
    """Average the points (and colours) that fall into the same cell of a grid of ``voxel_size``.

    Returns
    -------
    X_merged : (M, 3) ndarray
    colors_merged : (M, 3) uint8 ndarray or None
    counts : (M,) int ndarray
        How many points each merged point averages.

    Examples
    --------
    >>> X, c, n = merge_points([[0.1, 0.1, 0.1], [0.3, 0.3, 0.3], [1.5, 0.2, 0.2]], 1.0, [[0, 0, 0], [10, 20, 30],
    ...                                                                                  [1, 1, 1]])
    >>> X.tolist(), c.tolist(), n.tolist()
    ([[0.2, 0.2, 0.2], [1.5, 0.2, 0.2]], [[5, 10, 15], [1, 1, 1]], [2, 1])
    """
    X = as_points(X, "X", dim=3, min_n=0)
    voxel_size = as_positive(voxel_size, "voxel_size")
    if colors is not None:
        c = np.asarray(colors)
        if c.shape != (len(X), 3) or c.dtype.kind not in "iuf" or not np.all(np.isfinite(c)):
            raise ValueError(f"colors must have shape ({len(X)}, 3) (RGB per point); got shape {c.shape}")
    if len(X) == 0:
        return X.copy(), (None if colors is None else np.zeros((0, 3), np.uint8)), np.zeros(0, int)
    cell = np.floor((X - X.min(axis=0)) / voxel_size).astype(np.int64)
    _, inverse, counts = np.unique(cell, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse, X)
    X_merged = sums / counts[:, None]
    c_merged = None
    if colors is not None:
        csum = np.zeros((len(counts), 3))
        np.add.at(csum, inverse, np.asarray(colors, float))
        c_merged = np.clip(np.round(csum / counts[:, None]), 0, 255).astype(np.uint8)
    return X_merged, c_merged, counts


@dataclass
class FusedCloud:
    """What :func:`fuse_depth_maps` returns.

    Attributes
    ----------
    X : (N, 3) ndarray
        The fused points (world).
    colors : (N, 3) uint8 ndarray or None
    counts : (N,) int ndarray
        How many consistent depth-map points each fused point averages.
    n_points : int
        Points in all the depth maps together, before the test.
    n_consistent : int
        Of those, the ones confirmed by at least ``min_agree`` other maps.
    voxel_size : float
        The merging grid's cell.
    """

    X: np.ndarray = field(repr=False)
    colors: np.ndarray = field(repr=False)
    counts: np.ndarray = field(repr=False)
    n_points: int
    n_consistent: int
    voxel_size: float


def fuse_depth_maps(depth_maps: Sequence[DepthMap], *, rel_tol: float = 0.01, min_agree: int = 1,
                    voxel_size: float | None = None) -> FusedCloud:
    """Fuse depth maps: keep each map's points that ``min_agree`` other maps confirm, then merge on a grid.

    Parameters
    ----------
    depth_maps : list of DepthMap
        At least two.
    rel_tol : float
        Relative depth tolerance of the agreement test. A disparity error ``δd`` moves the depth by
        ``δZ / Z = δd / d``: for maps with disparities near ``d`` and errors up to ``δd`` pixels, ``δd / d``.
    min_agree : int
        Other maps that must confirm a point (its own map does not count).
    voxel_size : float, optional
        The merging cell (world units). Default: the median footprint of one pixel, ``Z / f``, over the maps.

    Returns
    -------
    FusedCloud
    """
    maps = _as_maps(depth_maps, min_n=2)
    rel_tol = as_positive(rel_tol, "rel_tol")
    if isinstance(min_agree, bool) or not isinstance(min_agree, (int, np.integer)) or not 1 <= min_agree < len(maps):
        raise ValueError(f"min_agree must be an integer in [1, {len(maps) - 1}] (other maps); got {min_agree!r}")
    if voxel_size is None:
        feet = [np.nanmedian(m.depth) / m.K[0, 0] for m in maps if m.n_valid]
        if not feet:
            raise ValueError("depth_maps hold no depth at all: nothing to fuse")
        voxel_size = float(np.median(feet))
    voxel_size = as_positive(voxel_size, "voxel_size")
    kept_X, kept_c, n_points = [], [], 0
    with_colors = all(m.colors is not None for m in maps)
    for k, m in enumerate(maps):
        X = m.points()
        n_points += len(X)
        agree = depth_agreement(X, [o for j, o in enumerate(maps) if j != k], rel_tol)
        keep = agree >= min_agree
        kept_X.append(X[keep])
        if with_colors:
            kept_c.append(m.point_colors()[keep])
    X = np.concatenate(kept_X) if kept_X else np.zeros((0, 3))
    colors = np.concatenate(kept_c) if with_colors else None
    X_m, c_m, counts = merge_points(X, voxel_size, colors)
    return FusedCloud(X_m, c_m, counts, n_points, len(X), voxel_size)
