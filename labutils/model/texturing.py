"""Colouring a mesh from the images: a depth buffer, visibility by a depth test, and vertex colours from the most
frontal unoccluded view (or averaged), with two measures of a texture.

1. **A depth buffer** (:func:`render_depth`): every triangle scan-converted into the image, its depth interpolated
   perspective-correctly (1/z is affine in the image), the nearest kept per pixel.
2. **Visibility** (:func:`vertex_views`): a vertex is seen by a view when it projects into the image, in front of
   the camera, faces it, and no part of the mesh is in front of it there (its depth is within ``depth_tol`` of the
   buffer's).
3. **Colour** (:func:`texture_vertices`): each vertex takes its colour from the view that sees it most frontally,
   ``argmax_v n · (C_v − X) / ‖C_v − X‖`` over the views that see it unoccluded (:func:`most_frontal_view`); the
   naive alternative averages every view it projects into, occluded or not.
4. **Measures** (:func:`edge_contrast`, :func:`held_out_error`): how sharp a texture is, and how well it predicts a
   view it was not made from.

Conventions: faces are counter-clockwise seen from outside; ``x_cam = R @ X + t``; pixel ``image[r, c]`` is
centred on ``(c, r)``.
"""
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..core.geometry import camera_center, pixels_and_depths
from ..core.validation import (
    as_array,
    as_cameras,
    as_image,
    as_image_size,
    as_indices,
    as_mesh,
    as_points,
    as_positive,
    as_visibility,
)
from .meshing import vertex_normals
from .pointcloud import sample_image

__all__ = ["render_depth", "VertexViews", "vertex_views", "most_frontal_view", "VertexTexture", "texture_vertices",
           "held_out_error", "edge_contrast"]


# --------------------------------------------------------------------------------------------------------------
# A depth buffer
# --------------------------------------------------------------------------------------------------------------
def render_depth(vertices: ArrayLike, faces: ArrayLike, K: ArrayLike, R: ArrayLike, t: ArrayLike,
                 image_size: tuple[int, int], *, chunk: int = 4_000_000) -> tuple[np.ndarray, np.ndarray]:
    """The depth buffer of a triangle mesh in one view: the nearest surface at every pixel centre.

    Each triangle is scan-converted over its bounding box of pixel centres; a pixel is inside when its three
    barycentric coordinates are ≥ 0 (a shared edge belongs to both triangles: no cracks). Its depth is interpolated
    perspective-correctly, ``1/z = Σ λ_k / z_k`` (1/z is affine in the image, z is not), and the nearest depth per
    pixel wins (a z-buffer; Catmull 1974).

    Parameters
    ----------
    vertices : (N, 3) array_like
    faces : (F, 3) int array_like
    K : (3, 3) array_like
    R : (3, 3) array_like
    t : (3,) array_like
        ``x_cam = R @ X + t``.
    image_size : (width, height)

    Returns
    -------
    depth : (H, W) ndarray
        Depth along the optical axis (``z`` of ``x_cam``), ``inf`` where no triangle covers the pixel.
    face : (H, W) int64 ndarray
        The nearest face at each pixel, -1 where none.

    Raises
    ------
    ValueError
        Shapes; a vertex of the mesh at or behind the camera's plane.

    Examples
    --------
    >>> V = np.array([[-1.0, -1, 4], [1, -1, 4], [0, 1, 2]])
    >>> depth, face = render_depth(V, [[0, 1, 2]], np.diag([2.0, 2.0, 1.0]) + [[0, 0, 2], [0, 0, 2], [0, 0, 0]],
    ...                            np.eye(3), np.zeros(3), (5, 5))
    >>> depth[2, 2], face[2, 2], face[0, 0]         # 1/z averaged: 3 = 1 / ((1/4 + 1/4 + 1/2) / 3), not 10/3
    (np.float64(3.0), np.int64(0), np.int64(-1))
    """
    V, F = as_mesh(vertices, faces)
    R, t = as_array(R, "R", "(3, 3)"), as_array(t, "t", "(3,)")
    if R.shape != (3, 3) or t.shape != (3,):
        raise ValueError(f"R must have shape (3, 3) and t shape (3,) (one view); got {R.shape} and {t.shape}")
    if not (np.isfinite(R).all() and np.isfinite(t).all()):
        raise ValueError("R and t must be finite (one registered view)")
    Ks, Rs, ts, _ = as_cameras(K, R[None], t[None])
    w, h = as_image_size(image_size)
    x, z = pixels_and_depths(Ks[0], Rs[0], ts[0], V)
    if np.any(z[F] <= 0):
        raise ValueError("a vertex of the mesh is at or behind the camera's plane: render_depth needs the whole mesh "
                         "in front of the camera")
    depth = np.full(h * w, np.inf)
    tri = x[F]                                             # (F, 3, 2)
    inv_z = 1.0 / z[F]                                     # (F, 3)
    c0 = np.maximum(np.ceil(tri[..., 0].min(1)), 0).astype(np.int64)
    c1 = np.minimum(np.floor(tri[..., 0].max(1)), w - 1).astype(np.int64)
    r0 = np.maximum(np.ceil(tri[..., 1].min(1)), 0).astype(np.int64)
    r1 = np.minimum(np.floor(tri[..., 1].max(1)), h - 1).astype(np.int64)
    nc, nr = np.maximum(c1 - c0 + 1, 0), np.maximum(r1 - r0 + 1, 0)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area = e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]                    # twice the signed area, pixels²
    todo = np.flatnonzero((nc * nr > 0) & (np.abs(area) > 1e-12))
    # per triangle, the barycentric coordinates λ1, λ2 of its 2nd and 3rd corner, and 1/z, as affine functions
    # a·col + b·row + c of the pixel: coef[f] = [[a, b, c] of λ1, of λ2, of 1/z]
    with np.errstate(divide="ignore", invalid="ignore"):
        l1 = np.stack([e2[:, 1], -e2[:, 0], e2[:, 0] * tri[:, 0, 1] - e2[:, 1] * tri[:, 0, 0]], 1) / area[:, None]
        l2 = np.stack([-e1[:, 1], e1[:, 0], e1[:, 1] * tri[:, 0, 0] - e1[:, 0] * tri[:, 0, 1]], 1) / area[:, None]
    iz = inv_z[:, :1] * np.array([0.0, 0.0, 1.0]) + l1 * (inv_z[:, 1:2] - inv_z[:, :1]) \
        + l2 * (inv_z[:, 2:3] - inv_z[:, :1])
    coef = np.stack([l1, l2, iz], axis=1)
    # triangles in buckets of equal (power-of-two) bounding-box size: each bucket is one broadcast over its pixels
    bw = 2 ** np.ceil(np.log2(np.maximum(nc[todo], 1))).astype(np.int64)
    bh = 2 ** np.ceil(np.log2(np.maximum(nr[todo], 1))).astype(np.int64)
    entries = []                                           # (pixel, depth, face) per bucket
    for sw, sh in set(zip(bw.tolist(), bh.tolist())):
        ks = todo[(bw == sw) & (bh == sh)]
        dc, dr = np.meshgrid(np.arange(sw), np.arange(sh))
        for k in np.array_split(ks, max(1, len(ks) * sw * sh // chunk)):
            col = c0[k, None] + dc.ravel()[None]          # (m, sw·sh)
            row = r0[k, None] + dr.ravel()[None]
            c = coef[k]
            l1 = c[:, 0, :1] * col + c[:, 0, 1:2] * row + c[:, 0, 2:]
            l2 = c[:, 1, :1] * col + c[:, 1, 1:2] * row + c[:, 1, 2:]
            inside = (l1 >= -1e-9) & (l2 >= -1e-9) & (l1 + l2 <= 1 + 1e-9) & (col <= c1[k, None]) \
                & (row <= r1[k, None])
            iz = c[:, 2, :1] * col + c[:, 2, 1:2] * row + c[:, 2, 2:]
            fid = np.broadcast_to(k[:, None], col.shape)
            entries.append((row[inside] * w + col[inside], 1.0 / iz[inside], fid[inside]))
    face = np.full(h * w, -1, np.int64)
    if entries:
        pix, dep, fid = (np.concatenate(a) for a in zip(*entries))
        np.minimum.at(depth, pix, dep)
        win = dep == depth[pix]
        face[pix[win]] = fid[win]
    return depth.reshape(h, w), face.reshape(h, w)


# --------------------------------------------------------------------------------------------------------------
# Visibility and colour
# --------------------------------------------------------------------------------------------------------------
@dataclass
class VertexViews:
    """How each view sees each vertex of a mesh (what :func:`vertex_views` returns).

    Attributes
    ----------
    inside : (V, N) bool ndarray
        The vertex projects into the view's image, in front of the camera (occluded or not).
    visible : (V, N) bool ndarray
        ``inside``, facing the camera (``cos > 0``) and not occluded: its depth is within ``depth_tol`` of the
        depth buffer's at its pixel.
    cos : (V, N) ndarray
        ``n · (C_v − X) / ‖C_v − X‖``: 1 when the view looks straight at the surface (NaN for views without a pose).
    colors : (V, N, 3) ndarray
        Bilinear samples of each image at the vertex's projection (NaN where not ``inside``).
    depth_tol : float
    """

    inside: np.ndarray
    visible: np.ndarray
    cos: np.ndarray
    colors: np.ndarray
    depth_tol: float

    @property
    def n_views(self):
        return self.visible.shape[0]


def vertex_views(vertices: ArrayLike, faces: ArrayLike, K: ArrayLike, R: ArrayLike, t: ArrayLike,
                 images: Sequence, *, depth_tol: float | None = None, buffer_scale: float = 0.5,
                 normals: ArrayLike | None = None) -> VertexViews:
    """Which views see each vertex unoccluded, how frontally, and the colour each view gives it.

    For each view with an image: the mesh's depth buffer (:func:`render_depth`); a vertex is visible when it
    projects into the image in front of the camera, faces it (``n · (C − X) > 0``, n the vertex normal) and its
    depth exceeds the buffer's at its nearest pixel by at most ``depth_tol`` (otherwise some other part of the
    mesh is in front of it).

    Parameters
    ----------
    vertices : (N, 3) array_like
    faces : (F, 3) int array_like
        Counter-clockwise seen from outside (the vertex normals point out).
    K : (3, 3) or (V, 3, 3) array_like
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
        ``x_cam = R @ X + t``; NaN for views that are not registered (they see nothing).
    images : sequence of V RGB images (or None)
        A view without an image sees nothing.
    depth_tol : float, optional
        World units; default: the mesh's median edge length.
    buffer_scale : float
        The depth buffer's resolution relative to the image's (0.5: half the width and height, a quarter of the
        work; occlusion is decided to within two pixels).
    normals : (N, 3) array_like, optional
        Outward unit normals of the vertices (default: :func:`vertex_normals`). A mesh through noisy points is
        jagged at the scale of its edges, and its vertex normals with it: the point cloud's PCA normals
        (:func:`labutils.model.orient_normals`) are then the better estimate.

    Returns
    -------
    VertexViews

    Examples
    --------
    >>> V = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])     # a square facing -z, the camera
    >>> img = np.full((60, 60, 3), 50, np.uint8)
    >>> K = np.array([[20.0, 0, 30], [0, 20, 30], [0, 0, 1]])
    >>> vv = vertex_views(V, [[0, 2, 1], [0, 3, 2]], K, np.eye(3)[None], [[0, 0, 5.0]], [img])
    >>> vv.visible.all(), vv.colors[0, 0].tolist()
    (np.True_, [50.0, 50.0, 50.0])
    """
    V, F = as_mesh(vertices, faces)
    Ks, R, t, registered = as_cameras(K, R, t)
    images = list(images)
    if len(images) != len(R):
        raise ValueError(f"images has {len(images)} entries for {len(R)} views: give one per view (None to skip)")
    if depth_tol is None:
        e = V[F] - V[F[:, [1, 2, 0]]]
        depth_tol = float(np.median(np.linalg.norm(e, axis=-1)))
    depth_tol = as_positive(depth_tol, "depth_tol")
    scale = as_positive(buffer_scale, "buffer_scale")
    if scale > 1:
        raise ValueError(f"buffer_scale must be in (0, 1]; got {buffer_scale!r}")
    # pixel centres at integers: the image spans [-½, W − ½]; scaled, x' = s x + (s − 1)/2
    S = np.array([[scale, 0, (scale - 1) / 2], [0, scale, (scale - 1) / 2], [0, 0, 1]])
    if normals is None:
        normals = vertex_normals(V, F)
    else:
        normals = as_points(normals, "normals", dim=3, like=(V, "vertices"))
        if np.any(np.abs(np.linalg.norm(normals, axis=1) - 1) > 1e-6):
            raise ValueError("normals must be unit vectors")
    C = camera_center(R, t)
    n_v, n = len(R), len(V)
    inside = np.zeros((n_v, n), bool)
    visible = np.zeros((n_v, n), bool)
    colors = np.full((n_v, n, 3), np.nan)
    with np.errstate(invalid="ignore"):
        d = C[:, None, :] - V[None]
        cos = np.einsum("vni,ni->vn", d, normals) / np.linalg.norm(d, axis=-1)
    for v in np.flatnonzero(registered):
        if images[v] is None:
            continue
        img = as_image(images[v], f"images[{v}]")
        if img.ndim != 3 or img.shape[2] < 3:
            raise ValueError(f"images[{v}] must be an RGB image (H, W, 3); got shape {img.shape}")
        h, w = img.shape[:2]
        x, z = pixels_and_depths(Ks[v], R[v], t[v], V)
        col, row = np.floor(x[:, 0] + 0.5), np.floor(x[:, 1] + 0.5)
        ok = (z > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        inside[v] = ok
        wb, hb = max(int(round(w * scale)), 1), max(int(round(h * scale)), 1)
        buf, _ = render_depth(V, F, S @ Ks[v], R[v], t[v], (wb, hb))
        xb = x[ok] * scale + (scale - 1) / 2
        cb = np.clip(np.floor(xb[:, 0] + 0.5), 0, wb - 1).astype(np.int64)
        rb = np.clip(np.floor(xb[:, 1] + 0.5), 0, hb - 1).astype(np.int64)
        depth_there = np.full(n, np.inf)
        depth_there[ok] = buf[rb, cb]
        visible[v] = ok & (cos[v] > 0) & (z <= depth_there + depth_tol)
        colors[v, ok] = sample_image(img[:, :, :3], np.clip(x[ok], 0, [w - 1, h - 1]))
    return VertexViews(inside, visible, cos, colors, depth_tol)


def most_frontal_view(X: ArrayLike, normals: ArrayLike, C: ArrayLike, visible: ArrayLike) -> np.ndarray:
    """For each point, the view that sees it most frontally: ``argmax_v n · (C_v − X) / ‖C_v − X‖`` over the
    views that see it.

    Parameters
    ----------
    X : (N, 3) array_like
    normals : (N, 3) array_like
        Outward unit normals.
    C : (V, 3) array_like
        Camera centres (NaN rows for views that are not registered: they must see nothing).
    visible : (V, N) bool array_like

    Returns
    -------
    (N,) int64 ndarray
        The view index, -1 for a point that no view sees.

    Examples
    --------
    >>> C = np.array([[0, 0, 10.0], [10, 0, 10], [0, 0, -10]])
    >>> most_frontal_view([[0, 0, 0.0], [0, 0, 0]], [[0.6, 0, 0.8], [0, 0, 1.0]], C, [[True, False], [True, False],
    ...                   [True, False]]).tolist()
    [1, -1]
    """
    X = as_points(X, "X", dim=3)
    normals = as_points(normals, "normals", dim=3, like=(X, "X"))
    C = as_array(C, "C", "(V, 3)")
    if C.ndim != 2 or C.shape[1] != 3 or len(C) == 0:
        raise ValueError(f"C must have shape (V, 3) (camera centres as rows, V >= 1); got shape {C.shape}")
    registered = np.all(np.isfinite(C), axis=1)
    if np.isinf(C).any() or (np.isnan(C).any(axis=1) & ~np.isnan(C).all(axis=1)).any():
        raise ValueError("C must be finite (a row entirely NaN marks a view that is not registered)")
    visible = as_visibility(visible, len(C), len(X), registered, views="C")
    d = np.where(registered[:, None, None], C[:, None, :], 0.0) - X[None]
    cos = np.einsum("vni,ni->vn", d, normals) / np.maximum(np.linalg.norm(d, axis=-1), np.finfo(float).tiny)
    best = np.argmax(np.where(visible, cos, -np.inf), axis=0)
    return np.where(visible.any(axis=0), best, -1).astype(np.int64)


@dataclass
class VertexTexture:
    """Vertex colours and where they came from (what :func:`texture_vertices` returns).

    Attributes
    ----------
    colors : (N, 3) uint8 ndarray
    view : (N,) int ndarray
        The view each colour was taken from (``'frontal'``), or -1 (averaged, or no view: ``fill``).
    coloured : (N,) bool ndarray
        False for the vertices that no usable view sees (they got ``fill``).
    """

    colors: np.ndarray
    view: np.ndarray
    coloured: np.ndarray

    @property
    def n_uncoloured(self):
        return int((~self.coloured).sum())


def texture_vertices(views: VertexViews, *, method: str = "frontal", exclude: Sequence[int] = (),
                     fill: tuple = (128, 128, 128)) -> VertexTexture:
    """Vertex colours from the images, three ways.

    ``'frontal'``: the colour in the view that sees the vertex most frontally and unoccluded
    (:func:`most_frontal_view`, on ``views.cos`` and ``views.visible``). ``'visible'``: the mean over the views
    that see it unoccluded. ``'average'``: the naive mean over every view it projects into, occluded or not.

    Parameters
    ----------
    views : VertexViews
    method : {'frontal', 'visible', 'average'}
    exclude : sequence of int
        Views not to use (e.g. one held out to judge the others).
    fill : (3,) uint8 colour
        For vertices that no usable view sees.

    Returns
    -------
    VertexTexture
    """
    if not isinstance(views, VertexViews):
        raise ValueError(f"views must be a VertexViews (from vertex_views); got {type(views).__name__}")
    if method not in ("frontal", "visible", "average"):
        raise ValueError(f"method must be 'frontal', 'visible' or 'average'; got {method!r}")
    fill_rgb = as_array(fill, "fill", "(3,)")
    if fill_rgb.shape != (3,) or not np.all((fill_rgb >= 0) & (fill_rgb <= 255)):
        raise ValueError(f"fill must be an RGB colour, 3 numbers in 0..255; got {fill!r}")
    use = np.ones(views.n_views, bool)
    for v in exclude:
        if not (isinstance(v, (int, np.integer)) and 0 <= v < views.n_views):
            raise ValueError(f"exclude holds view indices 0..{views.n_views - 1}; got {v!r}")
        use[v] = False
    mask = (views.inside if method == "average" else views.visible) & use[:, None]
    n = mask.shape[1]
    view = np.full(n, -1, np.int64)
    if method == "frontal":
        best = np.argmax(np.where(mask, views.cos, -np.inf), axis=0)
        seen = mask.any(axis=0)
        view[seen] = best[seen]
        col = np.full((n, 3), np.nan)
        col[seen] = views.colors[best[seen], np.flatnonzero(seen)]
    else:
        with np.errstate(invalid="ignore"):
            col = np.nansum(np.where(mask[..., None], views.colors, 0.0), axis=0) / mask.sum(0)[:, None]
        seen = mask.any(axis=0)
    out = np.empty((n, 3), np.uint8)
    out[seen] = np.clip(np.round(col[seen]), 0, 255)
    out[~seen] = np.round(fill_rgb).astype(np.uint8)
    return VertexTexture(out, view, seen)


def held_out_error(views: VertexViews, held_out: Sequence[int], *, method: str = "frontal",
                   min_cos: float = 0.5) -> np.ndarray:
    """How well a texture made without a view predicts that view: mean absolute colour difference (0..255).

    For each held-out view h: texture the vertices from the other views (:func:`texture_vertices` with
    ``exclude=[h]``), and compare, over the vertices that h sees unoccluded with ``cos ≥ min_cos``, their colour
    with h's image at their projection (mean over vertices and channels).

    Returns
    -------
    (len(held_out),) ndarray
    """
    if not isinstance(views, VertexViews):
        raise ValueError(f"views must be a VertexViews (from vertex_views); got {type(views).__name__}")
    held_out = as_indices(held_out, "held_out", views.n_views, what="view")
    errs = []
    for h in held_out:
        tex = texture_vertices(views, method=method, exclude=[h])
        sel = views.visible[h] & (views.cos[h] >= min_cos) & tex.coloured
        if not sel.any():
            raise ValueError(f"view {h} sees no vertex with cos >= {min_cos} that another view colours")
        errs.append(float(np.abs(tex.colors[sel].astype(float) - views.colors[h, sel]).mean()))
    return np.array(errs)


def edge_contrast(colors: ArrayLike, faces: ArrayLike) -> float:
    """Mean absolute difference of luminance (Rec. 601: 0.299 R + 0.587 G + 0.114 B) across the mesh's edges.

    A blurred texture has low contrast; a sharp one, high (noise raises it too: judge it beside a held-out error).

    >>> edge_contrast([[0, 0, 0], [255, 255, 255], [0, 0, 0]], [[0, 1, 2]])   # edges 0-1, 1-2 differ, 2-0 not
    170.0
    """
    c = as_array(colors, "colors", "(N, 3)")
    if c.ndim != 2 or c.shape[1] != 3:
        raise ValueError(f"colors must have shape (N, 3) (one RGB row per vertex); got shape {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ValueError(f"colors has non-finite values (NaN or inf) in rows "
                         f"{np.flatnonzero(~np.all(np.isfinite(c), axis=1))[:5].tolist()}")
    _, F = as_mesh(c, faces)                                 # one colour per vertex: faces index the rows of colors
    y = c @ np.array([0.299, 0.587, 0.114])
    e = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)
    return float(np.abs(y[e[:, 0]] - y[e[:, 1]]).mean())
