"""Plot helpers. Each takes an ``ax`` and returns it; none calls ``plt.show()`` or changes global style."""
import numpy as np
from matplotlib.ticker import MaxNLocator

from .metrics import align_cameras


def set_axes_equal(ax):
    """Give a 3D axis the same scale on x, y and z."""
    lims = np.array([ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d()])
    centre, half = lims.mean(1), (lims[:, 1] - lims[:, 0]).max() / 2
    ax.set_xlim3d(centre[0] - half, centre[0] + half)
    ax.set_ylim3d(centre[1] - half, centre[1] + half)
    ax.set_zlim3d(centre[2] - half, centre[2] + half)
    return ax


def few_ticks(ax, n=4):
    """At most ``n`` ticks on each axis of a 2D or 3D plot, so that the labels do not overlap; returns ``ax``."""
    axes = [ax.xaxis, ax.yaxis] + ([ax.zaxis] if hasattr(ax, "zaxis") else [])
    for axis in axes:
        axis.set_major_locator(MaxNLocator(n))
    return ax


def plot_view_errors(ax, errors, ylabel="rotation error (°)", width=0.8):
    """Per-view errors of several reconstructions as grouped bars (one group per view).

    Parameters
    ----------
    errors : dict str -> (V,) array_like
        A label and its per-view errors (NaN for a view that was not registered: no bar).
    ylabel : str
    width : float
        Width of one group of bars.

    The legend goes above the axes, so that it never hides a bar.
    """
    k = len(errors)
    w = width / max(k, 1)
    for n, (label, e) in enumerate(errors.items()):
        e = np.asarray(e, float)
        ax.bar(np.arange(e.size) + (n - (k - 1) / 2) * w, np.nan_to_num(e), w, label=label)
    ax.set_xlabel("view")
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=8, ncols=k, loc="lower left", bbox_to_anchor=(0, 1.0), frameon=False)
    return ax


def plot_cameras(ax, R, t, scale=0.1, color="C0", label=None, numbers=False):
    """Draw cameras as small pyramids on a 3D axis (``x_cam = R @ X + t``; the apex is the centre)."""
    R, t = np.asarray(R, float).reshape(-1, 3, 3), np.asarray(t, float).reshape(-1, 3)
    corners = scale * np.array([[-1, -0.75, 1.5], [1, -0.75, 1.5], [1, 0.75, 1.5], [-1, 0.75, 1.5]])
    for i, (Ri, ti) in enumerate(zip(R, t)):
        C = -Ri.T @ ti
        W = corners @ Ri + C                       # camera frame -> world: R.T @ (c - t)
        for w in W:
            ax.plot(*np.stack([C, w]).T, color=color, lw=0.8)
        ax.plot(*np.vstack([W, W[:1]]).T, color=color, lw=0.8, label=label if i == 0 else None)
        if numbers:
            ax.text(*C, str(i), color=color, fontsize=7)
    return ax


def plot_points(ax, X, color="k", size=1, label=None, **kwargs):
    """Scatter world points ``(N, 3)`` on a 3D axis."""
    X = np.asarray(X, float)
    ax.scatter(X[:, 0], X[:, 1], X[:, 2], s=size, c=color, label=label, depthshade=False, **kwargs)
    return ax


def image_frame(ax, image=None, image_size=None):
    """Show ``image`` on ``ax``, or set up an empty pixel frame of ``image_size`` (y pointing down)."""
    if image is not None:
        ax.imshow(image)
    elif image_size is not None:
        ax.set_xlim(0, image_size[0])
        ax.set_ylim(image_size[1], 0)
        ax.set_aspect("equal")
    return ax


def plot_image_points(ax, x, image=None, image_size=None, color="C1", size=4, label=None, **kwargs):
    """Pixels ``(N, 2)`` over an image (or an empty frame of ``image_size``), y pointing down."""
    x = np.asarray(x, float)
    image_frame(ax, image, image_size)
    ax.scatter(x[:, 0], x[:, 1], s=size, c=color, label=label, **kwargs)
    return ax


def plot_epipolar_lines(ax, F, x, image_size, which=2, color="C2", lw=0.7):
    """Draw the epipolar lines of points ``x`` in the other image (``x2ᵀ F x1 = 0``).

    Parameters
    ----------
    which : {1, 2}
        The image the lines are drawn in: 2 for ``l2 = F x1`` (x are points of image 1),
        1 for ``l1 = Fᵀ x2`` (x are points of image 2).
    """
    x_h = np.hstack([np.asarray(x, float), np.ones((len(x), 1))])
    lines = x_h @ (np.asarray(F).T if which == 2 else np.asarray(F))
    w, h = image_size
    xs = np.array([0.0, w])
    for a, b, c in lines:
        if abs(b) > 1e-12:
            ax.plot(xs, -(a * xs + c) / b, color=color, lw=lw)
        else:
            ax.plot([-c / a] * 2, [0, h], color=color, lw=lw)
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    return ax


def plot_noise_study(ax, study, pred=None, which="rot", color="C0", label=None, span=None, pred_label=None):
    """Pose error against pixel noise, log–log (notebook 06).

    Markers: the empirical RMS over cameras and trials of a :class:`labutils.noise_study.NoiseStudy`;
    error bars: the spread of the per-camera errors (16th to 84th percentile); dashed line: the
    predicted RMS ``σ · pred`` of a :class:`labutils.uncertainty.PosePrediction` made for σ = 1.
    ``which`` is ``'rot'`` (degrees) or ``'centre'`` (relative to the scene size). σ = 0 is left out.
    ``span = (σ_min, σ_max)`` sets the extent of the predicted line (default: the study's levels).
    ``pred_label`` labels the predicted line (default: ``label`` + ": predicted").
    """
    s = np.array(study.sigmas, float)
    pos = s > 0
    d = study.rot_deg if which == "rot" else study.centre_rel
    rms = study.rms(which)[pos]
    lo = np.array([np.nanpercentile(d[x], 16) for x in s[pos]])
    hi = np.array([np.nanpercentile(d[x], 84) for x in s[pos]])
    ax.errorbar(s[pos], rms, yerr=[np.clip(rms - lo, 0, None), np.clip(hi - rms, 0, None)], fmt="o", ms=5,
                capsize=3, color=color, label=label)
    if pred is not None:
        unit = pred.rot_rms_deg_all if which == "rot" else pred.centre_rms_rel_all
        lo_hi = (s[pos].min(), s[pos].max()) if span is None else span
        ss = np.array([lo_hi[0] / 1.5, lo_hi[1] * 1.5])
        if pred_label is None and label is not None:
            pred_label = f"{label}: predicted"
        ax.plot(ss, unit * ss, "--", color=color, lw=1, label=pred_label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(s[pos])
    ax.set_xticklabels([f"{x:g}" for x in s[pos]])
    ax.set_xticks([], minor=True)
    ax.set_xlabel("pixel noise σ (px)")
    ax.set_ylabel("rotation error (deg)" if which == "rot" else "centre error / scene size")
    return ax


def plot_pose_errors_topview(ax, R_true, t_true, R_est, t_est, magnify=50.0, axis_len=0.15):
    """Top view (x, y) of true cameras (black) and estimated ones after similarity alignment (red),
    with the errors of the centres and of the viewing directions magnified ``magnify`` times."""
    R_true, t_true = np.asarray(R_true, float), np.asarray(t_true, float)
    ok = np.all(np.isfinite(R_est), axis=(1, 2)) & np.all(np.isfinite(t_est), axis=1)
    R_al, t_al, _ = align_cameras(np.asarray(R_est)[ok], np.asarray(t_est)[ok], R_true[ok], t_true[ok])
    C = -np.einsum("vji,vj->vi", R_true, t_true)
    C_al = -np.einsum("vji,vj->vi", R_al, t_al)
    scale = axis_len * np.sqrt(((C - C.mean(0)) ** 2).sum(1).mean())
    C_show = C[ok] + magnify * (C_al - C[ok])
    z_true, z_al = R_true[:, 2], R_al[:, 2]              # viewing directions (third rows of R)
    z_show = z_true[ok] + magnify * (z_al - z_true[ok])
    for Ci, zi in zip(C, z_true):
        ax.plot(*np.stack([Ci, Ci + scale * zi])[:, :2].T, color="k", lw=0.8)
    for Ci, zi in zip(C_show, z_show):
        ax.plot(*np.stack([Ci, Ci + scale * zi])[:, :2].T, color="C3", lw=0.8)
    ax.plot(*C[:, :2].T, "k.", label="true")
    ax.plot(*C_show[:, :2].T, "o", color="C3", ms=3, label=f"estimated, errors x{magnify:g}")
    ax.set_aspect("equal")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    return ax


def plot_inliers(ax, x, x_proj, inliers, image=None, image_size=None, size=6):
    """Measured pixels split by a robust fit: inliers (green, with a segment to their reprojection
    ``x_proj``) and rejected points (red crosses), over an image or an empty frame of ``image_size``."""
    x, x_proj, inliers = np.asarray(x, float), np.asarray(x_proj, float), np.asarray(inliers, bool)
    plot_image_points(ax, x[inliers], image=image, image_size=image_size, color="limegreen", size=size,
                      label=f"inliers ({inliers.sum()})")
    for a, b in zip(x[inliers], x_proj[inliers]):
        ax.plot([a[0], b[0]], [a[1], b[1]], color="yellow", lw=0.8)
    ax.scatter(*x[~inliers].T, s=2 * size, c="red", marker="x", lw=0.8, label=f"rejected ({(~inliers).sum()})")
    return ax


def plot_matches(ax, x1, x2, inliers=None, image=None, image_size=None, size=6):
    """Correspondences drawn in image 1 as short segments ``x1 -> x2`` (the image motion).

    Inliers (all, when ``inliers`` is None) in green, outliers in red; over ``image`` or an empty frame
    of ``image_size`` (y pointing down).
    """
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    names = ("inliers", "outliers") if inliers is not None else ("matches", "")
    inliers = np.ones(len(x1), bool) if inliers is None else np.asarray(inliers, bool)
    image_frame(ax, image, image_size)
    for mask, color, label in ((inliers, "limegreen", names[0]), (~inliers, "red", names[1])):
        if mask.any():
            seg = np.stack([x1[mask], x2[mask]], axis=1)
            ax.plot(seg[:, :, 0].T, seg[:, :, 1].T, color=color, lw=0.8)
            ax.scatter(x1[mask, 0], x1[mask, 1], s=size, c=color, label=f"{label} ({mask.sum()})")
    return ax


def plot_two_view_from_above(ax, R, t, X, front=None, limit=None, scale=0.3):
    """A two-camera configuration seen from above: x against depth, in the frame of camera 1.

    Camera 1 is ``[I | 0]`` and camera 2 ``[R | t]``; each is drawn as a small triangle (its field of view)
    opening along its optical axis. Points ``X`` (N, 3) in camera-1 coordinates: green where ``front``
    (e.g. in front of both cameras), red elsewhere. ``limit`` fixes a square frame ``±limit``.
    """
    R, t, X = np.asarray(R, float), np.asarray(t, float).reshape(3), np.asarray(X, float)
    front = np.ones(len(X), bool) if front is None else np.asarray(front, bool)
    for Rc, tc, name in ((np.eye(3), np.zeros(3), "1"), (R, t, "2")):
        C = -Rc.T @ tc
        fan = np.array([[-0.6, 0, 1.0], [0.6, 0, 1.0]]) * scale @ Rc + C      # two rays of the view cone
        ax.plot([fan[0, 0], C[0], fan[1, 0]], [fan[0, 2], C[2], fan[1, 2]], color="C0", lw=1.5)
        ax.text(C[0], C[2], f" C{name}", color="C0", fontsize=8, va="top")
    ax.scatter(X[front, 0], X[front, 2], s=3, c="g", label="in front of both")
    ax.scatter(X[~front, 0], X[~front, 2], s=3, c="r", label="behind a camera")
    if limit is not None:
        ax.set_xlim(-limit, limit)
        ax.set_ylim(-limit, limit)
    ax.set_aspect("equal")
    ax.set_xlabel("x (camera 1)")
    ax.set_ylabel("depth z (camera 1)")
    return ax


def plot_sparsity(ax, A, n_camera_cols=None, markersize=0.3, title=None, color="k"):
    """Spy plot of a sparse matrix (a bundle-adjustment Jacobian or ``JᵀJ``), rows down, columns across.

    Parameters
    ----------
    A : scipy.sparse matrix or ndarray
    n_camera_cols : int, optional
        Number of camera columns (``k · V``): a red line separates them from the point columns (and,
        for a square matrix, the camera rows from the point rows).
    """
    ax.spy(A, markersize=markersize, aspect="auto", color=color)
    if n_camera_cols:
        ax.axvline(n_camera_cols - 0.5, color="C3", lw=0.8)
        if A.shape[0] == A.shape[1]:
            ax.axhline(n_camera_cols - 0.5, color="C3", lw=0.8)
    if title:
        ax.set_title(title, fontsize=10)
    ax.tick_params(labelsize=7)
    return ax
