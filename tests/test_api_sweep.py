"""A sweep of the public API with bad input, the way a careful user would try it (issue 8).

Every function in ``labutils.__all__`` gets a valid call (``VALID``) and, for each of its array and number
arguments, the typical mistakes: a transposed array, a NaN, an inf, a missing column, too few rows, an empty
array, a ragged list, a string, a negative or non-finite number, and no ``rng``. Each must raise ``ValueError``
whose message names the argument — never a plausible result, a silent NaN, or another exception type (numpy's
``IndexError``, ``ZeroDivisionError``...). The deliberately accepted cases are listed in ``ACCEPTED`` with the
reason. Degenerate geometry is swept in ``test_degenerate_geometry``.
"""
import inspect
import pkgutil
import re

import numpy as np
import pytest

import labutils as lu
from labutils.calibrate.chessboard import synthetic_board_views
from labutils.calibrate.lens import project_points
from labutils.core.scene import observations
from labutils.data.bal import BALProblem
from labutils.match import Features

S = lu.make_scene(40, 4, noise_px=0.5, rng=np.random.default_rng(0))
T = lu.make_scene(120, 8, layout="turntable", noise_px=0.3, rng=np.random.default_rng(1))
X1, X2, _ = S.pair(0, 1)
F = lu.fundamental_8point(X1, X2)
E = lu.essential_from_fundamental(F, S.K, S.K)
R01, T01 = lu.relative_pose(S.R[0], S.t[0], S.R[1], S.t[1])
CI, PI, XY = observations(S.x_meas)
CP = lu.camera_params_from_Rt(S.R, S.t)
REC = lu.incremental_sfm(T.tracks, T.K, rng=np.random.default_rng(0))
CIT, PIT, _ = observations(T.x_true)
P3 = S.X[:3]
x3 = lu.project(S.P[0], P3)

# the extensions: tiny scenes, so that the whole sweep stays cheap
PAIRS = np.array([[0, 1], [1, 2], [2, 3], [0, 3]])
R_REL = S.R[PAIRS[:, 1]] @ np.swapaxes(S.R[PAIRS[:, 0]], 1, 2)
DESC = np.random.default_rng(4).normal(size=(40, 16)).astype(np.float32)      # one descriptor per scene point
FEATS = [Features(S.x_meas[v], DESC + 0.01 * np.random.default_rng(5 + v).normal(size=DESC.shape).astype(np.float32),
                  image_size=(720, 576)) for v in range(4)]
VIEW_PAIRS = np.array([[0, 1], [1, 2], [2, 3]])
MATCHED = lu.match_views(FEATS, VIEW_PAIRS, rng=np.random.default_rng(0))
BLOCKS = (np.random.default_rng(7).uniform(size=(12, 16)) > 0.5).astype(np.uint8) * 255
TEXTURE = np.kron(BLOCKS, np.ones((4, 4), np.uint8))                   # 48 x 64, black and white blocks: corners
DIST = np.array([-0.2, 0.05, 0.001, -0.001, 0.0])
XN = np.random.default_rng(6).uniform(-0.4, 0.4, (10, 2))
BV = synthetic_board_views(rng=np.random.default_rng(0), n_views=4, noise_px=0.0, board=(5, 4))
OBJ = [BV.X] * 4
R_RIG, T_RIG = lu.rotation_from_angle_axis([0.0, 0.05, 0.0]), np.array([-0.1, 0.0, 0.0])
X_RIG = [project_points(BV.X, BV.K, BV.dist, R_RIG @ R, R_RIG @ t + T_RIG) for R, t in zip(BV.R, BV.t)]
CAL1 = lu.calibrate_camera(OBJ, BV.x_true, BV.image_size)
CAL2 = lu.calibrate_camera(OBJ, X_RIG, BV.image_size)
HS = np.stack([lu.board_homography(BV.X, x) for x in BV.x_true])
IMG = np.full((40, 40, 3), (40, 60, 200), np.uint8)
IMG[15:25, 15:25] = (230, 120, 20)
BG = lu.background_model([IMG, IMG])
BALL = np.array([[np.cos(a) * np.sin(b), np.sin(a) * np.sin(b), np.cos(b)]            # points on a unit sphere
                 for a in np.linspace(0, 2 * np.pi, 8, endpoint=False) for b in np.linspace(0.3, 2.8, 6)])
MESH = lu.delaunay_mesh(BALL, max_edge=10.0)
RB = np.stack([lu.rotation_from_angle_axis([0.0, a, 0.0]) for a in (0.0, 2.1, 4.2)])
TB = np.array([[0.0, 0.0, 4.0]] * 3)                                      # three cameras around the ball
KB = np.array([[30.0, 0, 20], [0, 30, 20], [0, 0, 1]])
VV = lu.vertex_views(MESH.vertices, MESH.faces, KB, RB, TB, [IMG] * 3)


def rng():
    return np.random.default_rng(3)


# name -> (positional args, keyword args); arrays are copied before every mutation
VALID = {
    "KRt_from_P": ((S.P[0],), {}),
    "P_from_KRt": ((S.K, S.R[0], S.t[0]), {}),
    "Rt_from_camera_params": ((CP,), {}),
    "align_cameras": ((S.R, S.t, S.R, S.t), {}),
    "align_similarity": ((S.X, 2 * S.X + 1), {}),
    "aligned_pose_covariance": ((T.R, T.t, T.X, CIT, PIT, T.K), {}),
    "angle_axis_from_rotation": ((S.R[0],), {}),
    "angle_between_deg": ((np.array([1.0, 0, 0]), np.array([1.0, 1, 0])), {}),
    "bearings": ((X1, S.K), {}),
    "bundle_adjust": ((S.R, S.t, S.X, CI, PI, XY, S.K), {}),
    "bundle_adjust_params": ((CP, S.X, CI, PI, XY, S.K), {}),
    "bundle_from_cameras": ((T.tracks, T.K, T.R, T.t), {}),
    "camera_center": ((S.R, S.t), {}),
    "camera_errors": ((REC, T.R, T.t), {}),
    "camera_params_from_Rt": ((S.R, S.t), {}),
    "cheirality_counts": ((E, X1, X2, S.K, S.K), {}),
    "decompose_essential": ((E,), {}),
    "dehomogeneous": ((np.hstack([X1, np.ones((len(X1), 1))]),), {}),
    "essential_from_fundamental": ((F, S.K, S.K), {}),
    "fundamental_7point": ((X1[:7], X2[:7]), {}),
    "fundamental_8point": ((X1, X2), {}),
    "fundamental_from_pose": ((S.K, S.K, R01, T01), {}),
    "fundamental_gold_standard": ((X1, X2), {}),
    "fundamental_ransac": ((X1, X2), {"rng": "RNG"}),
    "fundamental_residual": ((F, X1, X2), {}),
    "gauge_basis": ((S.R, S.t, S.X), {}),
    "homogeneous": ((X1,), {}),
    "incremental_sfm": ((T.tracks, T.K), {"rng": "RNG"}),
    "jacobian_sparsity": ((4, 40, CI, PI), {}),
    "left_jacobian_so3": ((np.array([0.1, 0.2, 0.3]),), {}),
    "make_scene": ((30, 3), {"rng": "RNG"}),
    "ml_residual_bound": ((1.0, 200, 150), {}),
    "observations": ((S.x_meas,), {}),
    "p3p": ((P3, x3, S.K), {}),
    "p3p_bearings": ((P3, lu.bearings(x3, S.K)), {}),
    "perturb_cameras": ((S.R, S.t), {"rng": "RNG"}),
    "pnp_ransac": ((S.X, S.x_meas[0], S.K), {"rng": "RNG"}),
    "pose_errors": ((S.R, S.t, S.R, S.t), {}),
    "pose_from_essential": ((E, X1, X2, S.K, S.K), {}),
    "predict_pose_errors": ((T.R, T.t, T.X, CIT, PIT, T.K), {}),
    "project": ((S.P[0], S.X), {}),
    "refine_pose": ((S.X, S.x_meas[0], S.K, S.R[0], S.t[0]), {}),
    "relative_pose": ((S.R[0], S.t[0], S.R[1], S.t[1]), {}),
    "reprojection_errors": ((S.X, S.x_meas[0], S.K, S.R[0], S.t[0]), {}),
    "reprojection_jacobian": ((CP, S.X, CI, PI, S.K), {}),
    "reprojection_residuals": ((CP, S.X, CI, PI, XY, S.K), {}),
    "right_jacobian_so3": ((np.array([0.1, 0.2, 0.3]),), {}),
    "rotation_error_deg": ((S.R[0], S.R[1]), {}),
    "rotation_from_angle_axis": ((np.array([0.1, 0.2, 0.3]),), {}),
    "sampson_distance": ((F, X1, X2), {}),
    "skew": ((np.array([1.0, 2.0, 3.0]),), {}),
    "triangulate": ((S.P[0], S.P[1], X1, X2), {}),
    "triangulate_multiview": ((S.P, S.x_meas), {}),
    "triangulate_optimal": ((F, X1, X2), {}),
    "triangulate_tracks": ((S.x_meas, np.stack([S.K] * 4), S.R, S.t, np.arange(4), S.visible),
                           {"threshold_px": 4.0, "min_angle_deg": 1.0}),
    "up_to_sign_scale": ((F, -2 * F), {}),
    # the extensions
    "gric_model_selection": ((X1, X2), {"sigma_px": 0.5}),
    "homography_dlt": ((X1, X2), {}),
    "hartley_normalisation": ((X1,), {}),
    "schur_step": ((CP, S.X, CI, PI, XY, S.K), {"mu": 1e-3}),
    "choose_initial_pair": ((T.tracks, T.K), {"rng": "RNG"}),
    "covisibility": ((T.tracks,), {}),
    "pyramid_score": ((X1, np.array([720.0, 576.0])), {"levels": 4}),
    "pose_covariance": ((S.X, S.K, S.R[0], S.t[0]), {"sigma": 0.5}),
    "chordal_rotation_averaging": ((PAIRS, R_REL, 4), {}),
    "ransac_iterations": ((0.5, 8, 0.99), {}),
    "match_descriptors": ((DESC, FEATS[1].descriptors), {"ratio": 0.8}),
    "match_views": ((FEATS, VIEW_PAIRS), {"rng": "RNG", "K": S.K}),
    "tracks_from_matches": ((FEATS, MATCHED), {"verify_px": 2.0}),
    "detect_features": ((TEXTURE,), {"scale": 0.5, "n_features": 50, "contrast_threshold": 0.04}),
    "distort": ((XN, DIST), {}),
    "undistort_points": ((lu.project(S.P[0], S.X), S.K, DIST), {}),
    "board_homography": ((BV.X, BV.x_true[0]), {}),
    "intrinsics_from_homographies": ((HS,), {}),
    "calibrate_camera": ((OBJ, BV.x_true, BV.image_size), {}),
    "calibrate_stereo": ((OBJ, BV.x_true, X_RIG, CAL1, CAL2), {}),
    "rectify_fusiello": ((S.K, S.K, R_RIG, T_RIG), {"image_size": (720, 576)}),
    "background_model": (([IMG, IMG],), {"border_px": 4}),
    "silhouette": ((IMG, BG), {"threshold": 2.5}),
    "estimate_normals": ((BALL,), {"k": 8}),
    "oriented_point_cloud": ((T.X, T.K, T.R, T.t, T.visible), {"k": 8}),
    "delaunay_mesh": ((BALL,), {"edge_factor": 8.0}),
    "vertex_views": ((MESH.vertices, MESH.faces, KB, RB, TB, [IMG] * 3), {}),
    "texture_vertices": ((VV,), {"fill": (128, 128, 128)}),
}

# Public names not swept here, and why.
NOT_SWEPT = {
    "BundleResult": "a result record", "GoldStandardResult": "a result record", "PnPResult": "a result record",
    "Reconstruction": "a result record", "Scene": "a record", "Views": "a record",
    "DataNotFoundError": "an exception", "data_dirs": "no arguments", "load_dino": "no arguments",
    "load_fountain": "no arguments", "load_temple": "no arguments",
    "find_data": "a path; tested in test_data_and_synthetic", "has_data": "a path",
    "load_scene": "passes its keywords to make_scene (swept)", "read_bal": "files: tested in test_bal",
    "write_bal": "files: tested in test_bal (write_bal checks the problem first)",
    "run_noise_study": "a harness of callables; its checks are tested in test_uncertainty",
    "ModelSelection": "a result record", "SchurStep": "a result record", "RotationAveragingResult": "a result record",
    "CalibrationResult": "a result record", "PointCloud": "a record", "VoxelGrid": "a record",
    "Carving": "a result record",
    "read_ply": "files: tested in test_ply", "write_points": "files: tested in test_ply (test_write_points_bad_input)",
    "write_mesh": "files: tested in test_ply (test_write_mesh_bad_faces)",
}

# (function, argument, mutation) -> why a successful call is right there.
ACCEPTED = {
    ("Rt_from_camera_params", "camera_params", "one_row"): "one camera is a valid set of cameras",
    ("Rt_from_camera_params", "camera_params", "empty"): "no cameras in, no poses out",
    ("bearings", "x", "one_row"): "one pixel has one ray",
    ("project", "X", "one_row"): "one point projects to one pixel",
    ("homogeneous", "x", "one_row"): "one point",
    ("homogeneous", "x", "empty"): "no points in, no points out",
    ("dehomogeneous", "x_h", "one_row"): "one point",
    ("dehomogeneous", "x_h", "empty"): "no points in, no points out",
    ("observations", "x", "one_row"): "one view of tracks is a valid (1, T, 2) array",
    ("gauge_basis", "X", "one_row"): "the gauge of cameras and one point is still 7-dimensional",
    ("ml_residual_bound", "sigma", "zero"): "no noise, no residual: the bound is 0",
    ("ml_residual_bound", "n_params", "zero"): "a problem with no free parameter: the bound is sigma",
    ("triangulate_tracks", "min_angle_deg", "zero"): "accept every triangulation angle",
    ("triangulate_tracks", "views", "drop_column"): "triangulating from 3 of the 4 views is valid",
    ("camera_center", "R", "nan"): "NaN marks a camera that is not there (an unregistered view): its centre is NaN",
    ("camera_center", "t", "nan"): "NaN marks a camera that is not there (an unregistered view): its centre is NaN",
    ("bundle_from_cameras", "R", "nan"): "a NaN row leaves that camera out (documented)",
    ("bundle_from_cameras", "t", "nan"): "a NaN row leaves that camera out (documented)",
    ("bundle_from_cameras", "tracks", "nan"): "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("incremental_sfm", "tracks", "nan"): "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("choose_initial_pair", "tracks", "nan"): "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("covisibility", "tracks", "nan"): "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("covisibility", "tracks", "one_row"): "one view: the 1 x 1 count of the tracks it sees",
    ("pyramid_score", "x", "one_row"): "one point fills one cell per level (the docstring's example)",
    ("pyramid_score", "x", "empty"): "no points score 0 (documented: N may be 0)",
    ("ransac_iterations", "inlier_ratio", "zero"): "no inliers: no number of trials is enough; the largest int64 "
                                                   "(documented) lets a RANSAC loop run on to max_iter",
    ("detect_features", "image", "transposed"): "a transposed image is an image (of the scene turned)",
    ("detect_features", "image", "drop_column"): "an image one column narrower is an image",
    ("detect_features", "image", "one_row"): "an image one pixel high is an image (without keypoints)",
    ("detect_features", "n_features", "zero"): "0 keeps every keypoint (documented)",
    ("detect_features", "contrast_threshold", "zero"): "0 keeps every extremum (the weakest threshold, as in OpenCV)",
    ("match_descriptors", "d1", "one_row"): "one descriptor has one nearest neighbour: at most one match",
    ("match_descriptors", "d1", "empty"): "no descriptors (a blank image, detect_features' example): no matches",
    ("match_descriptors", "d2", "one_row"): "one candidate has no second neighbour to refuse a match by ratio; the "
                                            "mutual check keeps at most one match",
    ("match_descriptors", "d2", "empty"): "no descriptors in image 2: no matches",
    ("match_views", "pairs", "one_row"): "one pair of views is a valid list of pairs",
    ("match_views", "pairs", "empty"): "no pairs to match: an empty MatchResult (no row in its table)",
    ("distort", "xn", "one_row"): "one point",
    ("distort", "xn", "empty"): "no points in, no points out",
    ("pose_covariance", "sigma", "zero"): "σ = 0: no pixel noise, the zero covariance (documented)",
    ("distort", "dist", "drop_column"): "4 coefficients mean k3 = 0 (documented, as in OpenCV)",
    ("undistort_points", "x", "one_row"): "one point",
    ("undistort_points", "x", "empty"): "no points in, no points out",
    ("undistort_points", "dist", "drop_column"): "4 coefficients mean k3 = 0 (documented, as in OpenCV)",
    ("background_model", "images", "one_row"): "one image is enough to learn the colours at its border",
    ("silhouette", "image", "one_row"): "an image one pixel high is an image",
    ("silhouette", "threshold", "zero"): "0 is the strictest threshold: every colour not seen at the border is object",
    ("vertex_views", "faces", "one_row"): "one triangle is a mesh (the vertices on no face face no camera)",
}
NAN_IS_DOCUMENTED = {("camera_center", "R", "nan"), ("camera_center", "t", "nan")}

# where a message rightly names the argument through the one it must agree with
ALIASES = {"bundle_adjust": {"X": "point_indices"}}


def _mutations(value):
    """(kind, bad value) pairs for one argument's valid value."""
    out = []
    if isinstance(value, (bool, np.bool_)) or value is None or isinstance(value, (str, lu.Reconstruction)):
        return out
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        return [("negative", -abs(value) - 1), ("nan", float("nan")), ("string", "three"), ("zero", 0)]
    a = np.asarray(value)
    if a.dtype.kind not in "fiub":
        return out
    if a.dtype.kind == "f":
        b = a.astype(float).copy()
        b.flat[min(1, b.size - 1)] = np.nan
        out.append(("nan", b))
        b = a.astype(float).copy()
        b.flat[min(1, b.size - 1)] = np.inf
        out.append(("inf", b))
    if a.ndim == 2 and a.shape[0] != a.shape[1]:
        out.append(("transposed", a.T.copy()))
    if a.ndim >= 1 and a.shape[-1] > 1:
        out.append(("drop_column", a[..., :-1].copy()))
    if a.ndim >= 1 and a.shape[0] > 1:
        out.append(("one_row", a[:1].copy()))
        out.append(("empty", a[:0].copy()))
    if a.ndim == 2:
        out.append(("ragged", [list(r) for r in a[:2]] + [list(a[2][:-1])] if len(a) > 2 else [[1.0], [1.0, 2.0]]))
    out.append(("string", "not an array"))
    return out


def _is_rng(v):
    return isinstance(v, str) and v == "RNG"


def _calls():
    for name, (args, kwargs) in VALID.items():
        fn = getattr(lu, name)
        params = list(inspect.signature(fn).parameters)
        for k, v in enumerate(args):
            for kind, bad in _mutations(v):
                yield name, params[k], kind, (args[:k] + (bad,) + args[k + 1:]), kwargs
        for key, v in kwargs.items():
            if _is_rng(v):
                for kind, bad in (("none", None), ("int", 42)):
                    yield name, key, kind, args, {**kwargs, key: bad}
            else:
                for kind, bad in _mutations(v):
                    yield name, key, kind, args, {**kwargs, key: bad}


CALLS = list(_calls())


def _run(name, args, kwargs):
    kwargs = {k: (rng() if _is_rng(v) else v) for k, v in kwargs.items()}
    return getattr(lu, name)(*args, **kwargs)


def test_every_public_function_is_swept():
    missing = sorted(set(lu.__all__) - set(VALID) - set(NOT_SWEPT))
    assert not missing, f"public names neither swept nor excused in NOT_SWEPT: {missing}"


def test_no_public_name_is_a_module_name():
    """Importing ``labutils.x`` sets the package's attribute ``x`` to the module, so a public name ``x`` that is also a
    module's (``ransac``, ``rotation_averaging``, ``global_sfm``, ``carve``) would be the function or the module
    depending on what was imported first; and ``import labutils.x as m`` would give the function once it is loaded."""
    modules = {m.name for m in pkgutil.iter_modules(lu.__path__)}
    both = sorted(set(lu.__all__) & modules)
    assert not both, f"public names that are also module names: {both}"


@pytest.mark.parametrize("name", sorted(VALID))
def test_valid_call_works(name):
    _run(name, *VALID[name])


def _nonfinite(out):
    """Whether a result holds NaN/inf where nothing says it may."""
    arrays = out if isinstance(out, tuple) else (out,)
    return any(isinstance(a, np.ndarray) and a.dtype.kind == "f" and not np.all(np.isfinite(a)) for a in arrays)


@pytest.mark.parametrize("name, arg, kind, args, kwargs", CALLS, ids=[f"{c[0]}-{c[1]}-{c[2]}" for c in CALLS])
def test_bad_input_is_refused_by_name(name, arg, kind, args, kwargs):
    if (name, arg, kind) in ACCEPTED:
        out = _run(name, args, kwargs)
        assert (name, arg, kind) in NAN_IS_DOCUMENTED or not _nonfinite(out), \
            f"{name}({arg}={kind}) is accepted ({ACCEPTED[name, arg, kind]}) but returns NaN"
        return
    try:
        out = _run(name, args, kwargs)
    except ValueError as exc:
        msg = str(exc)
        assert re.search(rf"\b{re.escape(arg)}\b", msg) or arg in ALIASES.get(name, {}) and \
            re.search(ALIASES[name][arg], msg), f"{name}({arg}={kind}): the message does not name {arg!r}: {msg}"
        return
    except Exception as exc:            # noqa: BLE001 - the point is to catch foreign exception types
        pytest.fail(f"{name}({arg}={kind}) raised {type(exc).__name__}: {exc}")
    pytest.fail(f"{name}({arg}={kind}) returned a result instead of refusing"
                + (" (with NaN/inf in it)" if _nonfinite(out) else ""))


# ---------------------------------------------------------------------------------------------------------------
# Degenerate geometry and out-of-range settings: each must be refused by name, or flagged in the result
# ---------------------------------------------------------------------------------------------------------------
def _pure_rotation():
    """Two cameras at the same centre (a pure rotation) and their images of random points."""
    R2 = lu.rotation_from_angle_axis([0.0, 0.2, 0.05])
    P1 = lu.P_from_KRt(S.K, np.eye(3), np.zeros(3))
    P2 = lu.P_from_KRt(S.K, R2, np.zeros(3))
    Xw = np.random.default_rng(0).uniform(-1, 1, (20, 3)) + [0, 0, 6]
    return P1, P2, lu.project(P1, Xw), lu.project(P2, Xw)


def _behind_start():
    """The scene's points mirrored through the first camera's centre: every point starts behind camera 0."""
    X = S.X.copy()
    C0 = lu.camera_center(S.R[0], S.t[0])
    return 2 * C0 - X


DEGENERATE = [
    ("triangulate with a pure rotation", lambda: lu.triangulate(*_pure_rotation()), "same centre"),
    ("triangulate_multiview with identical cameras",
     lambda: lu.triangulate_multiview(np.stack([S.P[0], 3 * S.P[0]]), np.stack([X1, X1])), "same centre"),
    ("fundamental_from_pose with t = 0", lambda: lu.fundamental_from_pose(S.K, S.K, R01, np.zeros(3)), "t is zero"),
    ("angle_axis_from_rotation of 2 I", lambda: lu.angle_axis_from_rotation(2 * np.eye(3)), "not a rotation"),
    ("angle_axis_from_rotation of a reflection", lambda: lu.angle_axis_from_rotation(np.diag([1.0, 1, -1])),
     "not a rotation"),
    ("angle_axis_from_rotation of zeros", lambda: lu.angle_axis_from_rotation(np.zeros((3, 3))), "not a rotation"),
    ("rotation_error_deg with an inf entry",
     lambda: lu.rotation_error_deg(np.where(np.eye(3) > 0, np.inf, 0.0), np.eye(3)), "R_est"),
    ("rotation_error_deg of the zero matrix", lambda: lu.rotation_error_deg(np.zeros((3, 3)), np.eye(3)),
     "not a rotation"),
    ("angle_between_deg with a zero vector", lambda: lu.angle_between_deg([0, 0, 0], [1, 0, 0]), "zero vector"),
    ("bundle_adjust with the points behind the cameras",
     lambda: lu.bundle_adjust(S.R, S.t, _behind_start(), CI, PI, XY, S.K), "behind"),
    ("bundle_adjust with a singular K",
     lambda: lu.bundle_adjust(S.R, S.t, S.X, CI, PI, XY, np.diag([800.0, 0.0, 1.0])), "singular"),
    ("bundle_adjust with a point at a camera centre",
     lambda: lu.bundle_adjust(S.R, S.t, np.vstack([lu.camera_center(S.R[0], S.t[0]), S.X[1:]]), CI, PI, XY, S.K),
     "centre|behind"),
    ("bundle_adjust with t transposed (V = 4)", lambda: lu.bundle_adjust(S.R, S.t.T, S.X, CI, PI, XY, S.K),
     "transposed"),
    ("camera_params_from_Rt with t transposed", lambda: lu.camera_params_from_Rt(S.R, S.t.T), "transposed"),
    ("triangulate_tracks with t transposed (V = 4)",
     lambda: lu.triangulate_tracks(S.x_meas, np.stack([S.K] * 4), S.R, S.t.T, np.arange(4), S.visible,
                                   threshold_px=2.0, min_angle_deg=1.0),
     "transposed"),
    ("project with X transposed", lambda: lu.project(S.P[0], S.X.T), "transposed"),
    ("project with pixels instead of points", lambda: lu.project(S.P[0], X1), r"shape \(N, 3\)"),
    ("make_scene with negative noise", lambda: lu.make_scene(20, 2, noise_px=-1, rng=rng()), "noise_px"),
    ("make_scene with outlier_ratio 1.5", lambda: lu.make_scene(20, 2, outlier_ratio=1.5, rng=rng()),
     "outlier_ratio"),
    ("make_scene with a singular K", lambda: lu.make_scene(20, 2, K=np.diag([1.0, 0, 1]), rng=rng()), "singular"),
    ("make_scene with min_views above n_views",
     lambda: lu.make_scene(20, 3, layout="turntable", min_views=5, rng=rng()), "min_views"),
    ("pnp_ransac with confidence 1", lambda: lu.pnp_ransac(S.X, S.x_meas[0], S.K, rng=rng(), confidence=1.0),
     "confidence"),
    ("incremental_sfm with -1 markers", lambda: lu.incremental_sfm(np.nan_to_num(T.tracks, nan=-1.0), T.K,
                                                                 rng=rng()), "-1"),
    ("bundle_from_cameras with identical cameras",
     lambda: lu.bundle_from_cameras(T.tracks, T.K, np.stack([T.R[0]] * len(T.R)), np.stack([T.t[0]] * len(T.R))),
     "no track could be triangulated|same centre"),
    ("bundle_from_cameras with mirrored cameras",
     lambda: lu.bundle_from_cameras(T.tracks, T.K, T.R, -T.t), "no track could be triangulated"),
    ("write_bal with a NaN point", lambda: lu.write_bal("/tmp/never.txt", BALProblem(
        np.zeros((1, 9)), np.array([[np.nan, 0, 1]]), np.zeros(1, int), np.zeros(1, int), np.zeros((1, 2)))),
     "points_3d"),
    ("write_bal with a point index out of range", lambda: lu.write_bal("/tmp/never.txt", BALProblem(
        np.zeros((1, 9)), np.zeros((1, 3)), np.zeros(1, int), np.array([3]), np.zeros((1, 2)))), "point_indices"),
    ("write_bal with 6-column cameras", lambda: lu.write_bal("/tmp/never.txt", BALProblem(
        np.zeros((1, 6)), np.zeros((1, 3)), np.zeros(1, int), np.zeros(1, int), np.zeros((1, 2)))),
     "camera_params"),
]


@pytest.mark.parametrize("what, call, message", DEGENERATE, ids=[d[0] for d in DEGENERATE])
def test_degenerate_geometry(what, call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_bundle_adjust_flags_points_that_end_behind():
    """What cannot be checked at the start is reported in the result: success is False when points end behind."""
    res = lu.bundle_adjust(S.R, S.t, S.X, CI, PI, XY, S.K)
    assert res.success and res.n_behind == 0
