"""Plot helpers. Each takes an ``ax`` and returns it; none calls ``plt.show()`` or changes global style."""
import numpy as np
from matplotlib.ticker import MaxNLocator

from ..core.geometry import camera_center
from ..core.metrics import align_cameras
from ..core.validation import as_array, as_mesh


def _points3(X, name="X"):
    """``X`` as a float ``(N, 3)`` array (NaN rows allowed: they are skipped), else ``ValueError`` — never reshaped,
    so a transposed ``(3, N)`` array is not drawn as garbage points."""
    a = as_array(X, name, "(N, 3)")
    if a.ndim != 2 or a.shape[1] != 3:
        hint = " — transposed? points are rows" if a.ndim == 2 and a.shape[0] == 3 else ""
        raise ValueError(f"{name} must have shape (N, 3) (points as rows); got shape {a.shape}{hint}")
    return a


def _poses(R, t):
    """Poses as ``(V, 3, 3)`` and ``(V, 3)`` arrays (NaN rows allowed: unregistered views); one camera may be given
    as ``(3, 3)`` and ``(3,)``. Anything else is a ``ValueError``, not a silent reshape."""
    R, t = as_array(R, "R", "(V, 3, 3)"), as_array(t, "t", "(V, 3)")
    if R.shape == (3, 3):
        R = R[None]
    if t.shape == (3,):
        t = t[None]
    if R.ndim != 3 or R.shape[1:] != (3, 3):
        raise ValueError(f"R must have shape (V, 3, 3) or (3, 3); got shape {R.shape}")
    if t.ndim != 2 or t.shape[1] != 3:
        hint = " — transposed? translations are rows" if t.ndim == 2 and t.shape[0] == 3 else ""
        raise ValueError(f"t must have shape (V, 3) or (3,) (one translation per row); got shape {t.shape}{hint}")
    if len(R) != len(t):
        raise ValueError(f"R has {len(R)} rotations but t has {len(t)} translations: one of each per camera")
    return R, t


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
    R, t = _poses(R, t)
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
    X = _points3(X)
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

    Markers: the empirical RMS over cameras and trials of a :class:`labutils.sfm.NoiseStudy`;
    error bars: the spread of the per-camera errors (16th to 84th percentile); dashed line: the
    predicted RMS ``σ · pred`` of a :class:`labutils.bundle.PosePrediction` made for σ = 1.
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
    ax.set_ylabel("rotation error (°)" if which == "rot" else "centre error / scene size")
    return ax


def plot_pose_errors_topview(ax, R_true, t_true, R_est, t_est, magnify=50.0, axis_len=0.15):
    """Top view (x, y) of true cameras (black) and estimated ones after similarity alignment (red),
    with the errors of the centres and of the viewing directions magnified ``magnify`` times."""
    R_true, t_true = np.asarray(R_true, float), np.asarray(t_true, float)
    ok = np.all(np.isfinite(R_est), axis=(1, 2)) & np.all(np.isfinite(t_est), axis=1)
    R_al, t_al, _ = align_cameras(np.asarray(R_est)[ok], np.asarray(t_est)[ok], R_true[ok], t_true[ok])
    C = camera_center(R_true, t_true)
    C_al = camera_center(R_al, t_al)
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


# --------------------------------------------------------------------------------------------------------------
# Interactive 3D: plotly (WebGL, offline — its JavaScript ships inside the Python package), with a static
# matplotlib fallback (static=True) for PDF export or a picture without JavaScript.
# --------------------------------------------------------------------------------------------------------------
def camera_frusta(R, t, K, image_size, scale):
    """Line segments drawing each camera as a pyramid: its centre joined to the four image corners at depth ``scale``.

    Parameters
    ----------
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
        Poses, ``x_cam = R @ X + t``; NaN rows (unregistered views) are skipped.
    K : (3, 3) or (V, 3, 3) array_like
    image_size : (width, height)
    scale : float
        Depth of the drawn image plane, in world units.

    Returns
    -------
    segments : (S, 2, 3) ndarray
        Eight segments per camera: four from the centre to the corners, four around the image.

    >>> camera_frusta(np.eye(3)[None], np.zeros((1, 3)), np.diag([100.0, 100.0, 1.0]), (200, 100), 1.0).shape
    (8, 2, 3)
    """
    R, t = _poses(R, t)
    Ks = np.broadcast_to(np.asarray(K, float), (len(R), 3, 3))
    w, h = image_size
    corners = np.array([[0, 0, 1], [w, 0, 1], [w, h, 1], [0, h, 1]], float)
    segments = []
    for Ri, ti, Ki in zip(R, t, Ks):
        if not (np.all(np.isfinite(Ri)) and np.all(np.isfinite(ti))):
            continue
        C = -Ri.T @ ti
        rays = corners @ np.linalg.inv(Ki).T                     # camera frame, z = 1
        W = (scale * rays - ti) @ Ri                              # world: Rᵀ (x_cam - t)
        segments += [[C, W[k]] for k in range(4)] + [[W[k], W[(k + 1) % 4]] for k in range(4)]
    return np.array(segments).reshape(-1, 2, 3)


def _scene_size(X, C):
    pts = np.vstack([a for a in (X, C) if a is not None and len(a)])
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    return float(np.linalg.norm(pts.max(0) - pts.min(0))) if len(pts) else 1.0


def _colors_rgb(colors, n):
    if colors is None:
        return None
    c = np.asarray(colors)
    if c.shape != (n, 3):
        raise ValueError(f"colors must have shape ({n}, 3) (RGB per point, 0..255 or 0..1); got {c.shape}")
    return c / 255.0 if c.dtype.kind in "ui" or c.max() > 1 else c


def show_reconstruction(X=None, colors=None, R=None, t=None, K=None, image_size=None, *, mesh=None,
                        frustum_scale=None, max_points=200_000, static=False, title=None, rng=None, normals=None,
                        normal_length=None, max_normals=3000):
    """An interactive 3D view of a reconstruction: points (coloured if given), cameras as frusta, a mesh.

    Rotate, zoom and pan with the mouse in JupyterLab; the view is drawn by the browser (WebGL), so it stays
    responsive with 10⁵ points and needs no running kernel. With ``static=True`` the same scene is drawn with
    matplotlib instead (a picture for a PDF, or where JavaScript is not run).

    Parameters
    ----------
    X : (N, 3) array_like, optional
        Points (NaN rows are skipped).
    colors : (N, 3) array_like, optional
        RGB per point, 0..255 (uint8) or 0..1.
    R, t, K, image_size : optional
        Cameras to draw as frusta (``x_cam = R @ X + t``; K shared or per view); without K and image_size a
        camera is drawn as a small pyramid of the same shape.
    mesh : (vertices, faces) or (vertices, faces, vertex_colors), optional
        A triangle mesh to draw too.
    frustum_scale : float, optional
        Depth of a drawn frustum (default 5 % of the scene's size).
    max_points : int
        Draw a random subset when there are more points (the subset is drawn with ``rng``, or the first
        ``max_points`` without one).
    static : bool
        Draw with matplotlib (returns its ``Figure``) instead of plotly.
    title : str, optional
    normals : (N, 3) array_like, optional
        A normal per point, drawn as a short segment from it (for at most ``max_normals`` points, every k-th).
    normal_length : float, optional
        Length of a drawn normal (default 2 % of the scene's size).

    Returns
    -------
    plotly.graph_objects.Figure, or matplotlib.figure.Figure with ``static=True``
        Display it by leaving it as the last expression of a cell.

    Examples
    --------
    >>> fig = show_reconstruction(np.random.default_rng(0).normal(size=(50, 3)), R=np.eye(3)[None],
    ...                           t=[[0, 0, 5.0]])
    >>> [trace.type for trace in fig.data]
    ['scatter3d', 'scatter3d']
    """
    X = None if X is None else _points3(X)
    keep = None if X is None else np.all(np.isfinite(X), axis=1)
    cols = None if X is None else _colors_rgb(colors, len(X))
    hedgehog = None
    if normals is not None:
        if X is None:
            raise ValueError("normals need the points X they belong to")
        N = np.asarray(normals, float)
        if N.shape != X.shape:
            raise ValueError(f"normals must have shape {X.shape} (one per point); got {N.shape}")
        every = max(1, int(np.ceil(keep.sum() / max_normals)))
        base, N = X[keep][::every], N[keep][::every]
        length = normal_length or 0.02 * _scene_size(X[keep], None)
        hedgehog = np.stack([base, base + length * N], axis=1)
    if X is not None:
        X, cols = X[keep], (None if cols is None else cols[keep])
        if len(X) > max_points:
            pick = (rng.choice(len(X), max_points, replace=False) if rng is not None else np.arange(max_points))
            X, cols = X[pick], (None if cols is None else cols[pick])
    C = None
    if R is not None:
        R, t = _poses(R, t)
        C = camera_center(R, t)
    scale = frustum_scale or 0.05 * _scene_size(X, C)
    segments = None
    if R is not None:
        Kd = np.diag([1.0, 1.0, 1.0]) if K is None else K
        size = (1.0, 0.75) if K is None or image_size is None else image_size
        if K is None:
            Kd = np.array([[1.0, 0, 0.5], [0, 1.0, 0.375], [0, 0, 1]])
        segments = camera_frusta(R, t, Kd, size, scale)
    if static:
        if hedgehog is not None:
            segments = hedgehog if segments is None else np.concatenate([segments, hedgehog])
        return _static_view(X, cols, segments, mesh, title)
    import plotly.graph_objects as go

    traces = []
    if X is not None:
        marker = dict(size=1.5, color=("rgb(40,40,40)" if cols is None else _rgb_strings(cols)))
        # _validate=False: plotly checks every colour string of 10⁵ points one by one (seconds); ours are well formed
        traces.append(go.Scatter3d(x=X[:, 0], y=X[:, 1], z=X[:, 2], mode="markers", marker=marker, name="points",
                                   hoverinfo="skip", _validate=False))
    if segments is not None and len(segments):
        xyz = np.concatenate([segments, np.full((len(segments), 1, 3), np.nan)], axis=1).reshape(-1, 3)
        traces.append(go.Scatter3d(x=xyz[:, 0], y=xyz[:, 1], z=xyz[:, 2], mode="lines", name="cameras",
                                   line=dict(color="royalblue", width=2), hoverinfo="skip"))
    if hedgehog is not None and len(hedgehog):
        xyz = np.concatenate([hedgehog, np.full((len(hedgehog), 1, 3), np.nan)], axis=1).reshape(-1, 3)
        traces.append(go.Scatter3d(x=xyz[:, 0], y=xyz[:, 1], z=xyz[:, 2], mode="lines", name="normals",
                                   line=dict(color="crimson", width=2), hoverinfo="skip"))
    if mesh is not None:
        traces.append(_mesh_trace(*mesh))
    fig = go.Figure(traces, _validate=False)
    fig.update_layout(scene=dict(aspectmode="data", xaxis_title="x", yaxis_title="y", zaxis_title="z"),
                      margin=dict(l=0, r=0, t=30 if title else 0, b=0), title=_title(title), showlegend=False,
                      height=520)
    return fig


def _title(title):
    """A plotly title as ``{"text": ...}``: figures built with ``_validate=False`` keep a bare string, which plotly.js
    (7) no longer draws."""
    return None if title is None else dict(text=str(title))


def _rgb_strings(cols):
    """'rgb(r,g,b)' strings of colours in 0..1."""
    c = np.clip(np.round(255 * np.asarray(cols, float)), 0, 255).astype(np.int64)
    return [f"rgb({r},{g},{b})" for r, g, b in c.tolist()]


def _mesh_trace(vertices, faces, vertex_colors=None):
    import plotly.graph_objects as go

    V, F = as_mesh(vertices, faces)
    kw = dict(color="lightgrey", flatshading=False)
    if vertex_colors is not None:
        c = _colors_rgb(vertex_colors, len(V))
        kw = dict(vertexcolor=_rgb_strings(c))
    return go.Mesh3d(x=V[:, 0], y=V[:, 1], z=V[:, 2], i=F[:, 0], j=F[:, 1], k=F[:, 2], name="mesh",
                     lighting=dict(ambient=0.5, diffuse=0.8, specular=0.1), hoverinfo="skip", _validate=False, **kw)


def show_mesh(vertices, faces, colors=None, *, static=False, title=None):
    """An interactive 3D view of a triangle mesh (per-vertex colours if given); ``static=True``: matplotlib.

    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]); F = np.array([[0, 1, 2], [0, 1, 3]])
    >>> show_mesh(V, F).data[0].type
    'mesh3d'
    """
    if static:
        return _static_view(None, None, None, (vertices, faces, colors), title)
    import plotly.graph_objects as go

    fig = go.Figure([_mesh_trace(vertices, faces, colors)], _validate=False)
    fig.update_layout(scene=dict(aspectmode="data"), margin=dict(l=0, r=0, t=30 if title else 0, b=0),
                      title=_title(title), height=520)
    return fig


def _static_view(X, cols, segments, mesh, title):
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    fig = plt.figure(figsize=(6, 5))
    ax = fig.add_subplot(projection="3d")
    if X is not None:
        ax.scatter(X[:, 0], X[:, 1], X[:, 2], s=0.5, c=cols if cols is not None else "k", depthshade=False)
    if segments is not None and len(segments):
        ax.add_collection3d(Line3DCollection(segments, colors="royalblue", linewidths=0.8))
    if mesh is not None:
        V, F = as_mesh(mesh[0], mesh[1])
        c = mesh[2] if len(mesh) > 2 and mesh[2] is not None else None
        face_col = "lightgrey" if c is None else _colors_rgb(c, len(V))[F].mean(1)
        ax.add_collection3d(Poly3DCollection(V[F], facecolors=face_col, edgecolors="none", alpha=1.0))
        X = V if X is None else np.vstack([X, V])
    pts = [a for a in (X, None if segments is None else segments.reshape(-1, 3)) if a is not None and len(a)]
    if pts:
        P = np.vstack(pts)
        ax.set_xlim(P[:, 0].min(), P[:, 0].max())
        ax.set_ylim(P[:, 1].min(), P[:, 1].max())
        ax.set_zlim(P[:, 2].min(), P[:, 2].max())
        set_axes_equal(ax)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z")
    if title:
        ax.set_title(title)
    return fig


def plot_cameras_and_points(ax, R=None, t=None, X=None, number_every=6, scale=0.08, color="C0", point_color="C3",
                            point_size=2, z_down=None, **kwargs):
    """Cameras and points on a 3D axis, with labelled axes and equal scales.

    Cameras (``x_cam = R @ X + t``) are drawn as pyramids by :func:`plot_cameras`, every ``number_every``-th one
    numbered just outside the ring they form (so the numbers stay legible for many cameras); points ``X (N, 3)``
    as dots of ``point_color`` (a colour, or one value per point with ``cmap=...`` in ``kwargs``).

    ``z_down``: draw the z axis pointing down. By default it does when the cameras' y axes (down in their images)
    point along +z on average, so the picture is upright as the cameras see the scene.
    """
    if R is not None:
        R, t = _poses(R, t)
        plot_cameras(ax, R, t, scale=scale, color=color)
        C = camera_center(R, t)
        centre = C.mean(0)
        for i in range(0, len(C), max(1, int(number_every))):
            out = C[i] - centre
            out[2] = 0.0
            n = np.linalg.norm(out)
            pos = C[i] + (2.5 * scale * out / n if n > 0 else 0.0)
            ax.text(*pos, str(i), color=color, fontsize=8, ha="center", va="center")
        if z_down is None:
            z_down = bool(R[:, 1, 2].mean() > 0)
    if X is not None:
        plot_points(ax, X, color=point_color, size=point_size, **kwargs)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z (pointing down)" if z_down else "z")
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(4))
    ax.tick_params(labelsize=7)
    set_axes_equal(ax)
    if z_down:
        ax.invert_zaxis()
    return ax
