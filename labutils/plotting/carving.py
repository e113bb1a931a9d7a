"""Plots for space carving: silhouettes over images, their agreement with a model's silhouette, a shaded mesh.

Each helper takes an ``ax`` and returns it; none calls ``plt.show()`` or changes global style.
"""
import numpy as np

__all__ = ["plot_mask", "plot_silhouette_agreement", "plot_mesh"]

AGREE, MASK_ONLY, MODEL_ONLY = (0.75, 0.75, 0.75), (0.85, 0.1, 0.1), (0.1, 0.45, 0.95)


def plot_mask(ax, mask, image=None, color=(1.0, 0.2, 0.8), alpha=0.45, title=None):
    """A silhouette as a tinted overlay on its image (or alone, white on black, without an image)."""
    mask = np.asarray(mask, bool)
    if image is None:
        ax.imshow(mask, cmap="gray", interpolation="nearest")
    else:
        img = np.asarray(image, float) / 255.0
        tint = img.copy()
        tint[mask] = (1 - alpha) * img[mask] + alpha * np.asarray(color)
        ax.imshow(tint, interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=9)
    return ax


def plot_silhouette_agreement(ax, mask, rendered, title=None):
    """Where a mask and a model's silhouette agree (grey), where only the mask is set (red: carved away by other
    views), where only the model is (blue); the IoU in the title."""
    mask, rendered = np.asarray(mask, bool), np.asarray(rendered, bool)
    img = np.ones(mask.shape + (3,))
    img[mask & rendered] = AGREE
    img[mask & ~rendered] = MASK_ONLY
    img[~mask & rendered] = MODEL_ONLY
    union = np.count_nonzero(mask | rendered)
    iou = np.count_nonzero(mask & rendered) / union if union else float("nan")
    ax.imshow(img, interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title((f"{title}: " if title else "") + f"IoU {iou:.3f}", fontsize=9)
    return ax


def plot_mesh(ax, vertices, faces, color=(0.85, 0.7, 0.45), light=(0.4, -0.5, -0.8), max_faces=40_000,
              view=None):
    """A triangle mesh on a 3D axis, flat-shaded by the angle between each face's normal and a light direction.

    Parameters
    ----------
    ax : a 3D axis (``projection='3d'``)
    vertices : (N, 3) array_like
    faces : (F, 3) int array_like
        Counter-clockwise seen from outside (the normals' side is lit).
    light : (3,)
        Direction the light comes *from*, world coordinates.
    max_faces : int
        Above this many faces every k-th face is drawn (matplotlib gets slow); pass a coarser mesh instead when
        it matters (``surface_mesh(..., step_size=2)``).
    view : (elev, azim), optional
    """
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    V = np.asarray(vertices, float)
    F = np.asarray(faces)
    if len(F) > max_faces:
        F = F[:: int(np.ceil(len(F) / max_faces))]
    tri = V[F]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    lvec = np.asarray(light, float) / np.linalg.norm(light)
    shade = 0.25 + 0.75 * np.clip(n @ lvec, 0, 1)
    colors = np.clip(shade[:, None] * np.asarray(color)[None], 0, 1)
    ax.add_collection3d(Poly3DCollection(tri, facecolors=colors, edgecolors="none", linewidths=0))
    lo, hi = V.min(axis=0), V.max(axis=0)
    c, r = (lo + hi) / 2, (hi - lo).max() / 2
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.set_box_aspect((1, 1, 1))
    if view is not None:
        ax.view_init(*view)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z")
    return ax
