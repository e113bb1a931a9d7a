"""Plot helpers for calibration (notebook 13). Each takes an ``ax`` and returns it; none calls ``plt.show()``."""
import numpy as np

from ..calibrate.chessboard import grid_line_residuals
from ..calibrate.lens import distort, undistort_points
from .common import few_ticks


def plot_corners(ax, x, board=(9, 6), image=None, image_size=None, color="C1", size=12, label=None):
    """Detected corners on the image, joined row by row (the first corner ringed: the order matters)."""
    if image is not None:
        ax.imshow(image, cmap="gray" if np.ndim(image) == 2 else None)
    elif image_size is not None:
        ax.set_xlim(-0.5, image_size[0] - 0.5)
        ax.set_ylim(image_size[1] - 0.5, -0.5)
        ax.set_aspect("equal")
    x = np.asarray(x, float)
    nx, ny = board
    for j in range(ny):
        ax.plot(*x[j * nx:(j + 1) * nx].T, "-", color=color, lw=0.8)
    ax.scatter(*x.T, s=size, color=color, label=label, zorder=3)
    ax.scatter(*x[0], s=8 * size, facecolors="none", edgecolors="red", lw=1.5, zorder=4)
    return ax


def plot_reprojection_errors(ax, residuals, names=None, magnify=None):
    """Scatter of the residuals ``x_proj - x`` (pixels), one colour per view, with the 1-px circle for scale."""
    for v, r in enumerate(residuals):
        ax.scatter(*np.asarray(r).T, s=4, label=None if names is None else names[v])
    a = np.linspace(0, 2 * np.pi, 100)
    ax.plot(np.cos(a), np.sin(a), "k:", lw=0.8)
    lim = magnify or max(1.1, 1.1 * max(np.abs(np.asarray(r)).max() for r in residuals))
    ax.set_xlim(-lim, lim)
    ax.set_ylim(lim, -lim)
    ax.set_aspect("equal")
    ax.set_xlabel("x error (px)")
    ax.set_ylabel("y error (px)")
    return ax


def plot_distortion_field(ax, K, dist, image_size, step=40, scale=1.0, color="C0"):
    """Arrows from where each pixel would be without the lens to where the lens puts it (length x ``scale``)."""
    w, h = image_size
    u, v = np.meshgrid(np.arange(step / 2, w, step), np.arange(step / 2, h, step))
    ideal = np.column_stack([u.ravel(), v.ravel()])
    xn = (ideal - K[:2, 2]) / [K[0, 0], K[1, 1]]
    real = distort(xn, dist) * [K[0, 0], K[1, 1]] + K[:2, 2]
    d = real - ideal
    ax.quiver(ideal[:, 0], ideal[:, 1], scale * d[:, 0], scale * d[:, 1], angles="xy", scale_units="xy", scale=1,
              color=color, width=0.003)
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_title(f"lens distortion (arrows x{scale:g}): ideal → observed pixel")
    return ax


def plot_view_influence(ax, names, share, dK_sigma=None):
    """Each view's share of the information on the intrinsics (bars), and |ΔK| in σ without it (dots, right axis)."""
    k = np.arange(len(names))
    ax.bar(k, 100 * np.asarray(share), color="C0", label="share of the information (%)")
    ax.set_xticks(k, [str(n).rsplit("/", 1)[-1].replace(".jpg", "") for n in names], rotation=60, fontsize=8)
    ax.set_ylabel("share of the information on K, dist (%)")
    if dK_sigma is not None:
        ax2 = ax.twinx()
        ax2.plot(k, np.abs(dK_sigma).max(axis=1), "o", color="C3", label="largest |ΔK| without the view (σ)")
        ax2.set_ylabel("largest |Δ(fx, fy, cx, cy)| without it, in σ", color="C3")
        ax2.set_ylim(bottom=0)
    return ax


def plot_rectified_pair(ax, image1, image2, n_lines=12, x1=None, x2=None, color="lime"):
    """Two rectified images side by side with horizontal lines: matching points must lie on the same line."""
    h, w = image1.shape[:2]
    ax.imshow(np.hstack([image1, image2]), cmap="gray" if np.ndim(image1) == 2 else None)
    for y in np.linspace(0, h - 1, n_lines + 2)[1:-1]:
        ax.axhline(y, color=color, lw=0.6)
    if x1 is not None and x2 is not None:
        ax.scatter(*np.asarray(x1).T, s=6, color="red")
        ax.scatter(np.asarray(x2)[:, 0] + w, np.asarray(x2)[:, 1], s=6, color="red")
    ax.set_xlim(-0.5, 2 * w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_axis_off()
    return ax


def plot_line_fits(ax, x, board=(9, 6), K=None, dist=None, color_before="C3", color_after="C2"):
    """How far each corner of each board row lies from the row's fitted straight line: measured, and undistorted.

    One curve per row (x: the corner's place in the row, y: its signed distance in pixels). A lens with barrel
    distortion bows the rows, so the measured curves are arcs; undistorted they are flat up to the corner noise.
    """
    nx, ny = board
    x = np.asarray(x, float)
    sets = [(x, color_before, "measured")]
    if K is not None:
        sets.append((undistort_points(x, K, dist), color_after, "undistorted"))
    for pts, c, lab in sets:
        d = grid_line_residuals(pts, board)[:nx * ny].reshape(ny, nx)
        for j in range(ny):
            ax.plot(np.arange(nx), d[j], "o-", color=c, ms=3, lw=0.8, label=lab if j == 0 else None)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("corner along the row")
    ax.set_ylabel("distance from the row's line (px)")
    ax.legend(fontsize=8)
    return ax


def plot_board_poses(ax, R, t, board=(9, 6), square=0.025, names=None, camera_size=0.05):
    """The boards of all views in the camera's frame, on a 3D axis (x right, y down, z forward; the camera at 0)."""
    nx, ny = board
    outline = np.array([[-1, -1, 0], [nx, -1, 0], [nx, ny, 0], [-1, ny, 0], [-1, -1, 0]], float) * square
    for v, (Rv, tv) in enumerate(zip(np.asarray(R), np.asarray(t))):
        P = outline @ Rv.T + tv
        ax.plot(P[:, 0], P[:, 2], -P[:, 1], lw=1)
        if names is not None:
            ax.text(*(P[0, [0, 2]]), -P[0, 1], str(names[v]).rsplit("/", 1)[-1].split(".")[0], fontsize=6)
    s = camera_size
    for c in np.array([[-1, -0.75, 1.5], [1, -0.75, 1.5], [1, 0.75, 1.5], [-1, 0.75, 1.5]]) * s:
        ax.plot([0, c[0]], [0, c[2]], [0, -c[1]], "k-", lw=0.8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z, forward (m)")
    ax.set_zlabel("-y, up (m)")
    ax.tick_params(labelsize=7)
    return few_ticks(ax, 4)                        # the metre ticks of a 3D axis overlap otherwise
