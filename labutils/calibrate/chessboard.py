"""The calibration board: its geometry, finding its corners in images, and rendering it with a known camera.

- :func:`board_points`: the inner corners of a chessboard as world points on the plane Z = 0, in the order
  OpenCV's detector returns them (row by row, x fastest);
- :func:`detect_corners`: OpenCV's ``findChessboardCorners`` and ``cornerSubPix`` (images and features are
  OpenCV's job in this workbook; the estimation that follows is ours, in :mod:`labutils.calibrate.camera`);
- :func:`synthetic_board_views` and :func:`render_board`: scene generation with exact truth — board poses a
  person might photograph, and the images a camera with known K and distortion would take of them, drawn with
  our own camera model and anti-aliased by supersampling;
- :func:`load_chessboard`: the real OpenCV sample views (``chessboard/left01.jpg`` ... on the data path), or the
  synthetic fallback with truth.
"""
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..core.geometry import rotation_from_angle_axis
from ..core.validation import as_count, as_image_size, as_points, as_positive, as_rotation, as_vector3
from ..data.paths import DataNotFoundError, find_data
from .lens import as_distortion, as_intrinsics, project_points, undistort_normalised

__all__ = ["board_points", "detect_corners", "grid_line_residuals", "BoardViews", "synthetic_board_views",
           "render_board", "render_board_views", "load_chessboard", "synthetic_stereo_views", "load_stereo_chessboard",
           "DEFAULT_K", "DEFAULT_DIST"]

#: The synthetic camera: close to the OpenCV sample camera (640×480), with a little fx/fy difference.
DEFAULT_K = np.array([[540.0, 0.0, 322.0], [0.0, 536.0, 238.0], [0.0, 0.0, 1.0]])
#: Its distortion (k1, k2, p1, p2, k3): barrel, like a webcam; invertible over the whole image.
DEFAULT_DIST = np.array([-0.25, 0.08, 0.0012, -0.0008, -0.01])

CHESSBOARD_HELP = """\
The chessboard views are not on the data path. Put OpenCV's sample images at <data>/chessboard/:
  chessboard/left01.jpg ... left14.jpg, right01.jpg ... right14.jpg (no 10), 640x480, 9x6 inner corners
  (OpenCV's samples/data, e.g. from the opencv-doc package), with left_intrinsics.yml beside them,
where <data> is $LABUTILS_DATA, the project's data/ folder, or ../shared/data/ beside the project."""


def _board(board):
    try:
        nx, ny = (as_count(v, "board") for v in board)
    except (TypeError, ValueError):
        raise ValueError(f"board must be (columns, rows) of inner corners, two integers, e.g. (9, 6); got {board!r}") \
            from None
    if nx < 2 or ny < 2:
        raise ValueError(f"board must have at least 2x2 inner corners; got {nx}x{ny}")
    return nx, ny


def board_points(board=(9, 6), square=0.025):
    """Inner corners of a chessboard on the plane Z = 0: ``(nx·ny, 3)``, row by row with x fastest.

    Corner ``(i, j)`` (column i, row j) is at ``(i·square, j·square, 0)``, row ``j·nx + i``: the order of
    ``cv2.findChessboardCorners(image, (nx, ny))``.

    Examples
    --------
    >>> board_points((3, 2), 0.5)
    array([[0. , 0. , 0. ],
           [0.5, 0. , 0. ],
           [1. , 0. , 0. ],
           [0. , 0.5, 0. ],
           [0.5, 0.5, 0. ],
           [1. , 0.5, 0. ]])
    """
    nx, ny = _board(board)
    if not (np.isfinite(square) and square > 0):
        raise ValueError(f"square must be a positive size; got {square!r}")
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    return np.column_stack([i.ravel() * square, j.ravel() * square, np.zeros(nx * ny)])


def detect_corners(image, board=(9, 6), *, refine=True, max_side=800):
    """Find the inner corners of a chessboard: OpenCV's detector, then sub-pixel refinement.

    ``cv2.findChessboardCorners`` finds the board and orders its corners row by row, in the order of
    :func:`board_points` or in exactly the reverse order (the grid of corners looks the same after a half turn;
    for one camera the pose absorbs it). ``cv2.cornerSubPix`` then moves each corner to the point that the image
    gradient around it is perpendicular to, to a few hundredths of a pixel on a sharp image (measured on rendered
    boards: 0.03–0.04 px). Its window is about as wide as the distance to the nearest neighbouring corner, at most
    11×11 pixels (``winSize = (5, 5)``), so that it does not reach the next corner; OpenCV's sample programs use
    ``winSize = (11, 11)`` (23×23), which on small squares biases the corners (see notebook 13).

    Parameters
    ----------
    image : (h, w) or (h, w, 3) uint8 ndarray
        Grey or BGR.
    board : (nx, ny)
        Inner corners per row and per column.
    refine : bool
        Run ``cornerSubPix``.
    max_side : int
        Larger images (a phone's 12 megapixels) are searched for the board at this size: OpenCV's detector slows down
        steeply with the image size (by orders of magnitude from 640×480 to a few megapixels). The corners are then
        refined at full resolution.

    Returns
    -------
    x : (nx·ny, 2) ndarray or None
        The corners in pixels (pixel centres at integer coordinates), None when the board is not found.
    """
    nx, ny = _board(board)
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim != 2 or img.size == 0:
        raise ValueError(f"image must be a grey (h, w) or colour (h, w, 3) array; got shape {img.shape}")
    if img.dtype != np.uint8:
        raise ValueError(f"image must be uint8 (0-255); got {img.dtype}")
    scale = min(1.0, max_side / max(img.shape))
    small = img if scale == 1.0 else cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    found, c = cv2.findChessboardCorners(small, (nx, ny), flags=cv2.CALIB_CB_ADAPTIVE_THRESH
                                         + cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not found or c is None or len(c) != nx * ny:
        return None
    if scale < 1.0:
        c = ((c + 0.5) / scale - 0.5).astype(np.float32)         # pixel centres at integer coordinates
    if refine:
        g = c.reshape(ny, nx, 2)
        spacing = min(np.linalg.norm(np.diff(g, axis=0), axis=2).min(),
                      np.linalg.norm(np.diff(g, axis=1), axis=2).min())
        half = int(np.clip(spacing / 2 - 1, 2, 5 / scale))
        c = cv2.cornerSubPix(img, c, (half, half), (-1, -1),
                             (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4))
    return c.reshape(-1, 2).astype(float)


# ---------------------------------------------------------------------------------------------------------------
# synthetic views with truth
# ---------------------------------------------------------------------------------------------------------------

@dataclass
class BoardViews:
    """Views of a chessboard: the images (if any), the detected or simulated corners, and the truth if known.

    Attributes
    ----------
    X : (N, 3) ndarray
        The board's corners (:func:`board_points`).
    x : list of (N, 2) ndarray
        Corners per view: detected (real images) or simulated with noise (synthetic).
    names : list of str
    image_size : (w, h)
    board : (nx, ny)
    square : float
    source : str
        ``'real'`` or ``'synthetic'``.
    images : list of uint8 ndarray, or None
    K, dist, R, t, x_true, noise_px :
        The truth (synthetic views only; None for real ones).
    """

    X: np.ndarray
    x: list
    names: list
    image_size: tuple
    board: tuple
    square: float
    source: str
    images: list = None
    K: np.ndarray = None
    dist: np.ndarray = None
    R: np.ndarray = None
    t: np.ndarray = None
    x_true: list = None
    noise_px: float = None
    rejected: list = field(default_factory=list)

    @property
    def n_views(self):
        return len(self.x)


def _random_board_pose(rng, K, dist, image_size, board, square, min_dist, max_dist, max_tilt_deg, margin_px,
                       also=None):
    nx, ny = board
    Xb = board_points(board, square)
    centre = np.array([(nx - 1) * square / 2, (ny - 1) * square / 2, 0.0])
    outline = np.array([[-1, -1, 0], [nx, -1, 0], [nx, ny, 0], [-1, ny, 0]], float) * square
    w, h = as_image_size(image_size)
    for _ in range(1000):
        axis = rng.normal(size=2)
        tilt = np.radians(rng.uniform(10, max_tilt_deg))
        R_tilt = rotation_from_angle_axis(np.r_[axis / np.linalg.norm(axis) * tilt, 0.0])
        R = R_tilt @ rotation_from_angle_axis([0.0, 0.0, np.radians(rng.uniform(-30, 30))])
        depth = rng.uniform(min_dist, max_dist)
        # aim the board's centre at a random spot in the middle 70 % of the image
        u, v = rng.uniform(0.15, 0.85) * w, rng.uniform(0.15, 0.85) * h
        ray = np.linalg.solve(K, [u, v, 1.0])
        t = depth * ray / ray[2] - R @ centre
        cams = [(K, dist, R, t)] + ([] if also is None else [(also[0], also[1], also[2] @ R, also[2] @ t + also[3])])
        try:
            xs = [project_points(np.vstack([Xb, outline]), *cam) for cam in cams]
        except ValueError:
            continue
        if all(x[:, 0].min() > margin_px and x[:, 0].max() < w - 1 - margin_px and x[:, 1].min() > margin_px
               and x[:, 1].max() < h - 1 - margin_px for x in xs):
            return R, t
    raise ValueError("could not place the board inside the image: make the board smaller or the distances larger")


def synthetic_board_views(n_views=12, noise_px=0.1, *, rng, K=None, dist=None, board=(9, 6), square=0.025,
                          image_size=(640, 480), distance=(0.3, 0.5), max_tilt_deg=45.0, margin_px=12.0, _also=None):
    """Random board poses, as a person photographing a board would take them, with exact corner projections.

    Each board is tilted by 10°–``max_tilt_deg`` about a random axis in its plane, turned by up to ±30° in it,
    placed at ``distance`` (m) with its centre seen in the middle 70 % of the image, and kept if the whole board
    (with a one-square white border) is inside the image.

    Parameters
    ----------
    n_views : int
    noise_px : float
        Standard deviation of the Gaussian noise added to each corner coordinate for ``x``.
    rng : numpy.random.Generator
        The poses and the noise (keyword-only, required).
    K, dist : optional
        The camera (default :data:`DEFAULT_K`, :data:`DEFAULT_DIST`); zero skew.

    Returns
    -------
    BoardViews
        ``source='synthetic'``, with the truth (``K, dist, R, t, x_true``); ``images`` is None (see
        :func:`render_board_views`).

    Examples
    --------
    >>> v = synthetic_board_views(n_views=3, noise_px=0.0, rng=np.random.default_rng(0))
    >>> v.n_views, v.x[0].shape, bool(np.allclose(v.x[0], v.x_true[0]))
    (3, (54, 2), True)
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator; got {type(rng).__name__}")
    n_views = as_count(n_views, "n_views", 1)
    noise_px = as_positive(noise_px, "noise_px", allow_zero=True)
    K = as_intrinsics(DEFAULT_K if K is None else K)
    dist = as_distortion(DEFAULT_DIST if dist is None else dist)
    board = _board(board)
    w, h = as_image_size(image_size)
    X = board_points(board, square)
    Rs, ts, x_true, x = [], [], [], []
    for _ in range(int(n_views)):
        R, t = _random_board_pose(rng, K, dist, (w, h), board, square, *distance, max_tilt_deg, margin_px, _also)
        xt = project_points(X, K, dist, R, t)
        Rs.append(R)
        ts.append(t)
        x_true.append(xt)
        x.append(xt + rng.normal(scale=noise_px, size=xt.shape) if noise_px > 0 else xt.copy())
    return BoardViews(X=X, x=x, names=[f"synthetic{v:02d}" for v in range(int(n_views))], image_size=(w, h),
                      board=board, square=square, source="synthetic", K=K, dist=dist, R=np.stack(Rs),
                      t=np.stack(ts), x_true=x_true, noise_px=float(noise_px))


def _corner_rays(K, dist, image_size):
    """Ideal normalised coordinates of every pixel *corner*, ``(h + 1, w + 1, 2)`` (shared by all views of a camera).

    Pixel centres are at integer coordinates, so pixel (i, j) spans ``[i - 0.5, i + 0.5] × [j - 0.5, j + 0.5]``.
    """
    w, h = as_image_size(image_size)
    u, v = np.meshgrid(np.arange(w + 1) - 0.5, np.arange(h + 1) - 0.5)
    xd = np.column_stack([((u - K[0, 2]) / K[0, 0]).ravel(), ((v - K[1, 2]) / K[1, 1]).ravel()])
    return undistort_normalised(xd, dist).reshape(h + 1, w + 1, 2)


def _shade(X, Y, front, nx, ny, margin):
    """Grey value of board coordinates (in squares): black 30 / white 225 squares, white border, grey 128 elsewhere."""
    on_board = front & (X >= -1 - margin) & (X <= nx + margin) & (Y >= -1 - margin) & (Y <= ny + margin)
    black = on_board & (X >= -1) & (X < nx) & (Y >= -1) & (Y < ny) & ((np.floor(X) + np.floor(Y)) % 2 == 0)
    return np.where(black, 30.0, np.where(on_board, 225.0, 128.0))


def render_board(K, dist, R, t, *, board=(9, 6), square=0.025, image_size=(640, 480), supersample=8, noise=0.0,
                 rng=None, margin=1.0, _rays=None):
    """Draw the image a camera ``(K, dist)`` takes of a chessboard at pose ``(R, t)``: anti-aliased, uint8, grey.

    Each pixel is the mean of the board's brightness over the pixel's area. The ray through each pixel corner is
    found by undoing the distortion (:func:`labutils.calibrate.lens.undistort_normalised`, Newton's method) and is cut
    with the board's plane (the inverse of the homography ``[r1 r2 t]``). A pixel whose four corners see the same
    colour is that colour; a pixel an edge crosses is the mean of ``supersample²`` samples, whose board
    coordinates are interpolated bilinearly between its corners' (within a pixel the map from image to board is
    affine to ~1e-4 px). The board has black (30) and white (225) squares and a white border of ``margin``
    squares, on a mid-grey background (128). Gaussian noise of ``noise`` grey levels is added last (``rng``
    required then).

    Returns
    -------
    image : (h, w) uint8 ndarray

    Examples
    --------
    >>> v = synthetic_board_views(n_views=1, noise_px=0.0, rng=np.random.default_rng(1))
    >>> img = render_board(v.K, v.dist, v.R[0], v.t[0])
    >>> img.shape, img.dtype, bool(np.abs(detect_corners(img) - v.x_true[0]).max() < 0.3)
    ((480, 640), dtype('uint8'), True)
    """
    K = as_intrinsics(K)
    dist = as_distortion(dist)
    R = as_rotation(R, "R")
    t = as_vector3(t, "t")
    nx, ny = _board(board)
    w, h = as_image_size(image_size)
    s = int(supersample)
    if s < 1:
        raise ValueError(f"supersample must be a positive integer; got {supersample!r}")
    if noise > 0 and not isinstance(rng, np.random.Generator):
        raise ValueError("noise > 0 needs rng, a numpy.random.Generator")
    rays = _corner_rays(K, dist, (w, h)) if _rays is None else _rays
    Hinv = np.linalg.inv(np.column_stack([R[:, 0], R[:, 1], t])) * [[1 / square], [1 / square], [1]]
    B = rays[..., 0, None] * Hinv[:, 0] + rays[..., 1, None] * Hinv[:, 1] + Hinv[:, 2]
    front = B[..., 2] > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        X, Y = np.where(front, B[..., 0] / B[..., 2], -1e9), np.where(front, B[..., 1] / B[..., 2], -1e9)
    c = _shade(X, Y, front, nx, ny, margin)                      # at the pixel corners, (h + 1, w + 1)
    img = c[:-1, :-1].copy()
    mixed = ~((c[:-1, :-1] == c[1:, :-1]) & (c[:-1, :-1] == c[:-1, 1:]) & (c[:-1, :-1] == c[1:, 1:]))
    mixed |= ~(front[:-1, :-1] & front[1:, :-1] & front[:-1, 1:] & front[1:, 1:]) & ~(
        ~front[:-1, :-1] & ~front[1:, :-1] & ~front[:-1, 1:] & ~front[1:, 1:])
    j, i = np.nonzero(mixed)
    if j.size:
        a = (np.arange(s) + 0.5) / s
        a, b = (g.ravel() for g in np.meshgrid(a, a))               # sub-sample offsets in the pixel, (s²,)
        wts = np.stack([(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b])        # bilinear weights, (4, s²)

        def interp(F):
            corners = np.stack([F[j, i], F[j, i + 1], F[j + 1, i], F[j + 1, i + 1]], axis=1)  # (n, 4)
            return corners @ wts
        Bs = [interp(B[..., k]) for k in range(3)]
        fs = Bs[2] > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            img[j, i] = _shade(np.where(fs, Bs[0] / Bs[2], -1e9), np.where(fs, Bs[1] / Bs[2], -1e9), fs, nx, ny,
                               margin).mean(axis=1)
    if noise > 0:
        img = img + rng.normal(scale=noise, size=img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def render_board_views(views, *, rng, supersample=8, noise=2.0):
    """Render every view of synthetic :class:`BoardViews` (:func:`render_board`), sharing the pixel rays."""
    if views.K is None:
        raise ValueError("views must be synthetic (with K, dist, R, t): real views already have images")
    rays = _corner_rays(views.K, views.dist, views.image_size)
    return [render_board(views.K, views.dist, R, t, board=views.board, square=views.square,
                         image_size=views.image_size, supersample=supersample, noise=noise, rng=rng, _rays=rays)
            for R, t in zip(views.R, views.t)]


# ---------------------------------------------------------------------------------------------------------------
# the real views
# ---------------------------------------------------------------------------------------------------------------

def load_chessboard(side="left", *, board=(9, 6), square=0.025):
    """The OpenCV sample chessboard views (``chessboard/left01.jpg`` ...) with their detected corners.

    Parameters
    ----------
    side : {'left', 'right'}
    board, square :
        9×6 inner corners, 25 mm squares (as ``left_intrinsics.yml`` records).

    Returns
    -------
    BoardViews
        ``source='real'``; ``images`` are the grey images; views whose board is not found are listed in
        ``rejected`` (none, for these images).

    Raises
    ------
    DataNotFoundError
        When the images are not on the data path (the message says where to get them).
    """
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right'; got {side!r}")
    folder = find_data(f"chessboard/{side}01.jpg", CHESSBOARD_HELP).parent
    paths = sorted(folder.glob(f"{side}[0-9][0-9].jpg"))
    if not paths:
        raise DataNotFoundError(f"no {side}NN.jpg in {folder}\n" + CHESSBOARD_HELP)
    images, xs, names, rejected = [], [], [], []
    for p in paths:
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        x = detect_corners(img, board) if img is not None else None
        if x is None:
            rejected.append({"image": p.name, "reason": "unreadable" if img is None else "board not found"})
            continue
        images.append(img)
        xs.append(x)
        names.append(p.name)
    h, w = images[0].shape
    return BoardViews(X=board_points(board, square), x=xs, names=names, image_size=(w, h), board=_board(board),
                      square=square, source="real", images=images, rejected=rejected)


#: The synthetic stereo rig's second camera: 8 cm to the right, turned by a degree or two, its own K and lens.
RIG_K2 = np.array([[545.0, 0.0, 318.0], [0.0, 542.0, 244.0], [0.0, 0.0, 1.0]])
RIG_DIST2 = np.array([-0.27, 0.1, -0.0006, 0.0009, -0.02])
RIG_R = rotation_from_angle_axis([0.004, -0.012, 0.007])
RIG_T = np.array([-0.08, 0.0008, 0.0004])


def _same_order(x, x_true):
    """The detector may list the corners from the other end (a half turn of the board): match the truth's order."""
    return x[::-1].copy() if np.abs(x[::-1] - x_true).max() < np.abs(x - x_true).max() else x


def synthetic_stereo_views(n_views=13, *, rng, noise=2.0):
    """Rendered views of the 9×6 board by a stereo rig with known truth, detected like real photos.

    Camera 1 is :data:`DEFAULT_K`, :data:`DEFAULT_DIST`; camera 2 is ``RIG_K2, RIG_DIST2`` at ``x_cam2 = RIG_R @
    x_cam1 + RIG_T`` (8 cm to the right, like OpenCV's sample rig). Each board pose is seen whole by both cameras;
    the images are drawn by :func:`render_board` (with grey-level noise ``noise``) and the corners found by
    :func:`detect_corners`, listed in the order of :func:`board_points`.

    Returns
    -------
    left, right : BoardViews
        ``source='synthetic'``, with images, detected corners ``x`` and the truth (``right.R, right.t`` are the
        board poses in camera 2).
    """
    left = synthetic_board_views(n_views, 0.0, rng=rng, distance=(0.3, 0.45), max_tilt_deg=50,
                                 _also=(RIG_K2, RIG_DIST2, RIG_R, RIG_T))
    R2, t2 = RIG_R @ left.R, left.t @ RIG_R.T + RIG_T
    right = BoardViews(X=left.X, x=[], names=[f"right{v:02d}" for v in range(n_views)], image_size=left.image_size,
                       board=left.board, square=left.square, source="synthetic", K=RIG_K2.copy(),
                       dist=RIG_DIST2.copy(), R=R2, t=t2,
                       x_true=[project_points(left.X, RIG_K2, RIG_DIST2, R, t) for R, t in zip(R2, t2)], noise_px=0.0)
    left.names = [f"left{v:02d}" for v in range(n_views)]
    for views in (left, right):
        views.images = render_board_views(views, noise=noise, rng=rng)
        found = [detect_corners(img, views.board) for img in views.images]
        if any(x is None for x in found):
            raise RuntimeError("a rendered board was not detected")     # does not happen with these poses
        views.x = [_same_order(x, xt) for x, xt in zip(found, views.x_true)]
        views.noise_px = None
    return left, right


def load_stereo_chessboard(*, rng, verbose=True):
    """The OpenCV sample stereo views if they are on the data path, else :func:`synthetic_stereo_views` (and say so).

    Returns
    -------
    left, right : BoardViews
        Pairs in the same order (``left.names[k]`` and ``right.names[k]`` are one moment).
    """
    try:
        left, right = load_chessboard("left"), load_chessboard("right")
        both = sorted(set(n[4:] for n in left.names) & set(n[5:] for n in right.names))
        for views, side in ((left, "left"), (right, "right")):
            keep = [views.names.index(side + n) for n in both]
            views.x, views.images, views.names = ([getattr(views, a)[k] for k in keep]
                                                  for a in ("x", "images", "names"))
        if verbose:
            w, h = left.image_size
            print(f"real data: OpenCV's sample stereo views, {len(both)} pairs of {w}x{h} images, "
                  f"{left.board[0]}x{left.board[1]} inner corners, {left.square} m squares")
        return left, right
    except DataNotFoundError as exc:
        if verbose:
            print(f"{str(exc).splitlines()[0]}\nusing synthetic views instead: a rendered stereo rig with known K, "
                  "distortion and poses")
        return synthetic_stereo_views(rng=rng)


def grid_line_residuals(x, board=(9, 6)):
    """How straight the board's rows and columns of corners are: perpendicular distances to fitted lines.

    Each row (nx corners) and each column (ny corners) gets its total-least-squares line (through the centroid,
    along the principal direction); a perfect pinhole image of a flat board has all distances 0 (up to noise),
    while lens distortion bends the lines (barrel: outwards).

    Parameters
    ----------
    x : (nx·ny, 2) array_like
        Corners in the order of :func:`board_points`.
    board : (nx, ny)

    Returns
    -------
    d : (ny·nx + nx·ny,) ndarray
        Signed distances in pixels, rows first; ``sqrt(mean(d²))`` is the straightness residual.

    Examples
    --------
    >>> x = board_points((4, 3), 10.0)[:, :2] + 5
    >>> float(np.abs(grid_line_residuals(x, (4, 3))).max())
    0.0
    """
    nx, ny = _board(board)
    x = as_points(x, "x")
    if x.shape != (nx * ny, 2):
        raise ValueError(f"x must have shape ({nx * ny}, 2) for a {nx}x{ny} board; got {x.shape}")
    g = x.reshape(ny, nx, 2)
    lines = [g[j] for j in range(ny)] + [g[:, i] for i in range(nx)]
    out = []
    for pts in lines:
        c = pts - pts.mean(0)
        normal = np.linalg.svd(c)[2][-1]
        out.append(c @ normal)
    return np.concatenate(out)
