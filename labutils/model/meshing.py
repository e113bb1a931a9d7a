"""Meshes from points: Delaunay tetrahedra carved from the outside through long edges, their boundary, and normals.

The 3D Delaunay tetrahedralisation of the points (scipy's Qhull) fills their convex hull, bridging gaps and
concavities the surface does not. :func:`delaunay_mesh` carves them away from the outside inwards: starting outside
the hull, a flood fill enters a tetrahedron through any face with an edge longer than ``max_edge`` (by default a
multiple of the median nearest-neighbour spacing) — Boissonnat's sculpting (ACM TOG 1984), close to an alpha shape
(Edelsbrunner & Mücke, ACM TOG 1994). Tetrahedra it cannot reach are the solid, even the large ones inside; the
surface is the set of faces that belong to exactly one solid tetrahedron (:func:`boundary_faces`), each turned to
face out of it: closed, and with no inner shell (deleting every tetrahedron with a long edge would hollow the object
out and leave two layers of faces at its surface). Visibility could carve more — the space between a camera and a
point it sees is empty (Labatut, Pons & Keriven, ICCV 2007, with a graph cut); deleting every tetrahedron a line of
sight crosses, without one, erodes the surface where the points are noisy.

Colouring a mesh from the images is :mod:`labutils.model.texturing`. Faces are counter-clockwise seen from outside
(normals point out, as :func:`labutils.model.surface_mesh` makes them).
"""
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import Delaunay, QhullError, cKDTree

from ..core.validation import as_mesh, as_points, as_positive

__all__ = ["DelaunayMesh", "delaunay_mesh", "boundary_faces", "face_normals", "vertex_normals"]


# --------------------------------------------------------------------------------------------------------------
# Normals
# --------------------------------------------------------------------------------------------------------------
def face_normals(vertices: ArrayLike, faces: ArrayLike) -> np.ndarray:
    """Unit normals of triangles, ``(b − a) × (c − a)`` normalised (outward for counter-clockwise faces).

    Raises ``ValueError`` for a degenerate (zero-area) face.

    >>> face_normals(np.eye(3), [[0, 1, 2]]).round(3)
    array([[0.577, 0.577, 0.577]])
    """
    V, F = as_mesh(vertices, faces)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    length = np.linalg.norm(n, axis=1)
    if np.any(length == 0):
        raise ValueError(f"face {int(np.flatnonzero(length == 0)[0])} has zero area: its normal is undefined")
    return n / length[:, None]


def vertex_normals(vertices: ArrayLike, faces: ArrayLike) -> np.ndarray:
    """Unit vertex normals: the area-weighted sum of the normals of the faces around each vertex.

    A vertex in no face gets the normal (0, 0, 0).

    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    >>> vertex_normals(V, [[0, 1, 2], [1, 3, 2]])
    array([[0., 0., 1.],
           [0., 0., 1.],
           [0., 0., 1.],
           [0., 0., 1.]])
    """
    V, F = as_mesh(vertices, faces)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])     # length = 2 × area
    acc = np.zeros_like(V)
    for k in range(3):
        np.add.at(acc, F[:, k], n)
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    return np.divide(acc, length, out=np.zeros_like(acc), where=length > 0)


# --------------------------------------------------------------------------------------------------------------
# A Delaunay mesh
# --------------------------------------------------------------------------------------------------------------
_TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])   # face k: opposite vertex k, out of the tet


def boundary_faces(tetrahedra: ArrayLike, points: ArrayLike) -> np.ndarray:
    """The faces that belong to exactly one of the given tetrahedra, each turned to face out of its tetrahedron.

    Parameters
    ----------
    tetrahedra : (T, 4) int array_like
        Vertex indices into ``points``.
    points : (N, 3) array_like

    Returns
    -------
    (F, 3) int64 ndarray
        Counter-clockwise seen from outside the union of the tetrahedra.

    Examples
    --------
    >>> P = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    >>> len(boundary_faces([[0, 1, 2, 3], [1, 2, 3, 4]], P))     # two tetrahedra sharing a face: 6 faces out of 8
    6
    """
    X = as_points(points, "points", dim=3)
    try:
        T = np.asarray(tetrahedra)
    except ValueError as exc:
        raise ValueError(f"tetrahedra must be a (T, 4) integer array: {exc}") from None
    if T.ndim != 2 or T.shape[1] != 4 or (T.size and T.dtype.kind not in "iu"):
        raise ValueError(f"tetrahedra must be a (T, 4) integer array; got shape {T.shape}")
    if T.size and (T.min() < 0 or T.max() >= len(X)):
        raise ValueError(f"tetrahedra hold indices {int(T.min())}..{int(T.max())}, but points has {len(X)} rows")
    if len(T) == 0:
        return np.zeros((0, 3), np.int64)
    T = T.astype(np.int64)
    # orient each tetrahedron positively: (b − a) × (c − a) · (d − a) > 0 makes _TET_FACES point outward
    a, b, c, d = (X[T[:, k]] for k in range(4))
    neg = np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) < 0
    T = np.where(neg[:, None], T[:, [0, 2, 1, 3]], T)
    faces = T[:, _TET_FACES].reshape(-1, 3)
    _, inv, count = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    return faces[count[inv.ravel()] == 1]


@dataclass
class DelaunayMesh:
    """What :func:`delaunay_mesh` returns.

    Attributes
    ----------
    vertices : (M, 3) ndarray
        The points the surface uses.
    faces : (F, 3) int64 ndarray
        Counter-clockwise seen from outside.
    point_index : (M,) int ndarray
        Which input point each vertex is (to carry colours and normals over).
    max_edge : float
        The edge length through which the carving passed.
    spacing : float
        The median distance from a point to its nearest neighbour.
    n_tetrahedra : int
        Of the full Delaunay tetrahedralisation.
    n_removed : int
        Tetrahedra carved away.
    """

    vertices: np.ndarray
    faces: np.ndarray
    point_index: np.ndarray
    max_edge: float
    spacing: float
    n_tetrahedra: int
    n_removed: int


def delaunay_mesh(X: ArrayLike, *, max_edge: float | None = None, edge_factor: float = 8.0) -> DelaunayMesh:
    """A surface from points: Delaunay tetrahedra, carved from outside through long edges, the boundary of the rest.

    Parameters
    ----------
    X : (N, 3) array_like
        Points, N >= 4, not all on one plane.
    max_edge : float, optional
        The carving from outside passes through faces with a longer edge. Default: ``edge_factor`` times the
        median distance from a point to its nearest neighbour.
    edge_factor : float

    Returns
    -------
    DelaunayMesh

    Raises
    ------
    ValueError
        Shapes, NaN, fewer than 4 points, points on one plane (no tetrahedra), or nothing left after filtering.

    Examples
    --------
    >>> g = np.stack(np.meshgrid(*[np.arange(3.0)] * 3, indexing="ij"), -1).reshape(-1, 3)   # a 3x3x3 cube
    >>> m = delaunay_mesh(g + np.random.default_rng(0).normal(scale=1e-3, size=g.shape), max_edge=1.9)
    >>> len(m.vertices), len(m.faces)                # the 26 points on the cube's surface, 2 triangles per square
    (26, 48)
    """
    X = as_points(X, "X", dim=3, min_n=4)
    edge_factor = as_positive(edge_factor, "edge_factor")
    try:
        tri = Delaunay(X)
    except QhullError as exc:
        raise ValueError(f"X: no Delaunay tetrahedra (are the points on one plane?): {str(exc).splitlines()[0]}") \
            from None
    T = tri.simplices
    spacing = float(np.median(cKDTree(X).query(X, k=2)[0][:, 1]))
    if max_edge is None:
        max_edge = edge_factor * spacing
    max_edge = as_positive(max_edge, "max_edge")
    keep = ~_sculpt(tri, X, max_edge)
    F = boundary_faces(T[keep], X)
    if len(F) == 0:
        raise ValueError(f"no tetrahedron is left (max_edge = {max_edge:.3g}, median spacing {spacing:.3g}): raise "
                         "max_edge")
    used, F = np.unique(F, return_inverse=True)
    return DelaunayMesh(X[used], F.reshape(-1, 3).astype(np.int64), used, float(max_edge), spacing, len(T),
                        int((~keep).sum()))


def _sculpt(tri, X, max_edge):
    """(T,) bool: the tetrahedra reached from outside the convex hull through faces with an edge longer than
    ``max_edge`` (a flood fill over the tetrahedra's face adjacency; Boissonnat 1984)."""
    T = tri.simplices
    n = len(T)
    faces = T[:, _TET_FACES]                                             # (T, 4, 3): face k is opposite vertex k
    P = X[faces]
    longest = np.linalg.norm(P - P[:, :, [1, 2, 0]], axis=-1).max(axis=-1)
    wide = longest > max_edge
    j, k = np.nonzero(wide)
    other = tri.neighbors[j, k]
    other = np.where(other < 0, n, other)                               # node n: the outside of the hull
    graph = coo_matrix((np.ones(len(j)), (j, other)), shape=(n + 1, n + 1))
    _, label = connected_components(graph, directed=False)
    return label[:n] == label[n]
