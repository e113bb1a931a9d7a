"""The carved volume's surface (marching cubes, scikit-image), a mesh's silhouette in a view and its IoU with the
masks, and the colour threshold chosen by how well the silhouettes agree."""
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike
from skimage.measure import marching_cubes

from ...core.validation import as_array, as_image_size, as_mesh
from .silhouettes import _as_number, clean_mask, mask_iou, signed_distance_map
from .voxels import (
    Carving,
    VoxelGrid,
    _as_cameras,
    _carve_maps,
    _check_masks,
    bounding_box_from_silhouettes,
    project_with_depth,
)

__all__ = ["surface_mesh", "mesh_volume", "render_silhouette", "silhouette_ious", "THRESHOLD_CANDIDATES",
           "choose_threshold"]


def surface_mesh(carving: Carving, *, level: float = 0.0, step_size: int = 1
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    if not isinstance(carving, Carving):
        raise ValueError(f"carving must be a Carving (from carve); got {type(carving).__name__}")
    level = _as_number(level, "level")
    step_size = _as_number(step_size, "step_size", lo=1, integer=True)
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


def mesh_volume(vertices: ArrayLike, faces: ArrayLike) -> float:
    """Signed volume of a closed triangle mesh (positive when the faces are counter-clockwise seen from outside).

    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> round(mesh_volume(V, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])), 6)
    0.166667
    """
    V, F = as_mesh(vertices, faces)
    a, b, c = (V[F[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def render_silhouette(vertices: ArrayLike, faces: ArrayLike, P: ArrayLike, image_size: tuple[int, int]) -> np.ndarray:
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
    V, F = as_mesh(vertices, faces, allow_empty=True)
    w, h = as_image_size(image_size)
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


def silhouette_ious(vertices: ArrayLike, faces: ArrayLike, masks: Sequence[ArrayLike], P: ArrayLike) -> np.ndarray:
    """Per view: the IoU of the mesh's silhouette (:func:`render_silhouette`) with that view's mask.

    Returns
    -------
    (V,) ndarray
    """
    P = _as_cameras(P)
    masks = _check_masks(masks, len(P))
    return np.array([mask_iou(render_silhouette(vertices, faces, Pv, m.shape[::-1]), m) for Pv, m in zip(P, masks)])


THRESHOLD_CANDIDATES = (0.5, 1.5, 2.5, 3.5, 5.0)


def _as_distance_map(d, name):
    """A finite real (H, W) colour-distance map, or ``ValueError`` naming it."""
    a = as_array(d, name, "(H, W)")
    if a.ndim != 2 or a.size == 0 or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite (H, W) map of colour distances; got shape {a.shape}"
                         + ("" if a.ndim != 2 or a.size == 0 else " with NaN or inf"))
    return a
"""Colour thresholds tried by :func:`choose_threshold` (CIELAB units, lightness weighted)."""


def choose_threshold(distances: Sequence[ArrayLike], P: ArrayLike, *,
                     candidates: Sequence[float] = THRESHOLD_CANDIDATES, n: int = 40, every: int = 1,
                     min_component: float = 0.02, max_hole: float = 0.002) -> tuple[float, np.ndarray]:
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
    distances = [_as_distance_map(d, f"distances[{i}]") for i, d in enumerate(distances)]
    if len(distances) != len(P):
        raise ValueError(f"distances has {len(distances)} maps for {len(P)} cameras: one per view")
    candidates = sorted(_as_number(c, "candidates", lo=0) for c in candidates)
    if not candidates:
        raise ValueError("candidates is empty: give at least one threshold")
    n = _as_number(n, "n", lo=4, integer=True)
    every = _as_number(every, "every", lo=1, integer=True)
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
