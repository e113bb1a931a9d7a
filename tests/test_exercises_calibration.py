"""Notebook 13's self-checks: the reference solutions pass every case, and typical mistakes get their own hint."""
import numpy as np
import pytest
from _exercises import assert_passes, assert_stubs_not_written, hints

from labutils.calibrate.lens import distort
from labutils.calibrate.rectification import rectify_fusiello
from labutils.calibrate.zhang import intrinsics_from_homographies
from labutils.exercises.ex13_calibration import check_distort_points, check_rectifying_rotation, check_zhang_intrinsics

# --- the reference solutions, as written in the notebook ---------------------------------------------------------

def zhang_reference(Hs):
    def v(H, i, j):
        hi, hj = H[:, i], H[:, j]
        return np.array([hi[0] * hj[0], hi[0] * hj[1] + hi[1] * hj[0], hi[1] * hj[1],
                         hi[2] * hj[0] + hi[0] * hj[2], hi[2] * hj[1] + hi[1] * hj[2], hi[2] * hj[2]])
    V = np.vstack([[v(H, 0, 1), v(H, 0, 0) - v(H, 1, 1)] for H in Hs])
    b = np.linalg.svd(V)[2][-1]
    B = np.array([[b[0], b[1], b[3]], [b[1], b[2], b[4]], [b[3], b[4], b[5]]])
    if B[0, 0] < 0:
        B = -B
    K = np.linalg.inv(np.linalg.cholesky(B).T)
    return K / K[2, 2]


def distort_reference(xn, dist):
    k1, k2, p1, p2, k3 = dist
    x, y = xn[:, 0], xn[:, 1]
    r2 = x ** 2 + y ** 2
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    return np.column_stack([x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x ** 2),
                            y * radial + p1 * (r2 + 2 * y ** 2) + 2 * p2 * x * y])


def rectifying_reference(R, t):
    C2 = -R.T @ t
    x = C2 / np.linalg.norm(C2)
    y = np.cross([0.0, 0.0, 1.0], x)
    y /= np.linalg.norm(y)
    return np.stack([x, y, np.cross(x, y)])


@pytest.mark.parametrize("check, solution", [(check_zhang_intrinsics, zhang_reference),
                                             (check_zhang_intrinsics, intrinsics_from_homographies),
                                             (check_distort_points, distort_reference),
                                             (check_distort_points, distort),
                                             (check_rectifying_rotation, rectifying_reference)])
def test_reference_solutions_pass(check, solution):
    assert_passes(check, solution)


def test_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_zhang_intrinsics)


# --- exercise 1: typical mistakes ---------------------------------------------------------------------------------

def test_zhang_rows_instead_of_columns():
    assert "column" in hints(check_zhang_intrinsics(lambda Hs: zhang_reference(np.swapaxes(Hs, 1, 2)), verbose=False))


def test_zhang_returns_inverse():
    def wrong(Hs):
        K = zhang_reference(Hs)
        Ki = np.linalg.inv(K)
        return Ki / Ki[2, 2]
    assert "K⁻¹" in hints(check_zhang_intrinsics(wrong, verbose=False))


def test_zhang_returns_cholesky_factor():
    assert "Cholesky factor L" in hints(check_zhang_intrinsics(lambda Hs: np.linalg.inv(zhang_reference(Hs)).T,
                                                               verbose=False))


def test_zhang_forgets_sign():
    def wrong(Hs):
        def v(H, i, j):
            hi, hj = H[:, i], H[:, j]
            return np.array([hi[0] * hj[0], hi[0] * hj[1] + hi[1] * hj[0], hi[1] * hj[1],
                             hi[2] * hj[0] + hi[0] * hj[2], hi[2] * hj[1] + hi[1] * hj[2], hi[2] * hj[2]])
        V = np.vstack([[v(H, 0, 1), v(H, 0, 0) - v(H, 1, 1)] for H in Hs])
        b = np.linalg.svd(V)[2][-1]
        b = -b if b[0] > 0 else b                 # the unlucky sign, always
        B = np.array([[b[0], b[1], b[3]], [b[1], b[2], b[4]], [b[3], b[4], b[5]]])
        K = np.linalg.inv(np.linalg.cholesky(B).T)
        return K / K[2, 2]
    assert "up to sign" in hints(check_zhang_intrinsics(wrong, verbose=False))


def test_zhang_one_equation_per_view():
    def wrong(Hs):
        def v(H, i, j):
            hi, hj = H[:, i], H[:, j]
            return np.array([hi[0] * hj[0], hi[0] * hj[1] + hi[1] * hj[0], hi[1] * hj[1],
                             hi[2] * hj[0] + hi[0] * hj[2], hi[2] * hj[1] + hi[1] * hj[2], hi[2] * hj[2]])
        V = np.vstack([v(H, 0, 1) for H in Hs])           # only h1ᵀ B h2 = 0
        b = np.linalg.svd(np.vstack([V, np.zeros((6, 6))]))[2][-1]
        B = np.array([[b[0], b[1], b[3]], [b[1], b[2], b[4]], [b[3], b[4], b[5]]])
        B = -B if B[0, 0] < 0 else B
        K = np.linalg.inv(np.linalg.cholesky(B).T)
        return K / K[2, 2]
    assert "two* equations" in hints(check_zhang_intrinsics(wrong, verbose=False))


def test_zhang_not_normalised():
    assert "K[2, 2]" in hints(check_zhang_intrinsics(lambda Hs: 3.0 * zhang_reference(Hs), verbose=False))


# --- exercise 2 ------------------------------------------------------------------------------------------------

def test_distort_swapped_tangential():
    def wrong(xn, d):
        return distort_reference(xn, [d[0], d[1], d[3], d[2], d[4]])
    assert "swapped" in hints(check_distort_points(wrong, verbose=False))


def test_distort_rounding_passes_and_float32_gets_its_hint():
    assert_passes(check_distort_points, lambda xn, d: distort_reference(xn, d) + 1e-11)   # another order of operations

    def in_float32(xn, d):
        return distort_reference(xn.astype(np.float32), np.asarray(d, np.float32))
    assert "compute in float64" in hints(check_distort_points(in_float32, verbose=False))

    def swapped_in_float32(xn, d):
        return distort_reference(xn.astype(np.float32), np.asarray([d[0], d[1], d[3], d[2], d[4]], np.float32))
    assert "swapped" in hints(check_distort_points(swapped_in_float32, verbose=False))


def test_distort_r_instead_of_r2():
    def wrong(xn, d):
        k1, k2, p1, p2, k3 = d
        r = np.linalg.norm(xn, axis=1)
        out = distort_reference(xn, [0, 0, p1, p2, 0])
        return out + xn * (k1 * r + k2 * r ** 2 + k3 * r ** 3)[:, None]
    assert "uses r instead of r²" in hints(check_distort_points(wrong, verbose=False))


def test_distort_without_k3():
    assert "k3 is missing" in hints(check_distort_points(lambda xn, d: distort_reference(xn, [*d[:4], 0.0]),
                                                         verbose=False))


def test_distort_without_tangential():
    assert "tangential terms (p1, p2) are missing" in hints(
        check_distort_points(lambda xn, d: distort_reference(xn, [d[0], d[1], 0, 0, d[4]]), verbose=False))


# --- exercise 3 ------------------------------------------------------------------------------------------------

def test_rectifying_baseline_reversed():
    def wrong(R, t):
        Rr = rectifying_reference(R, t)
        return np.stack([-Rr[0], -Rr[1], Rr[2]])
    assert "from camera 2 to camera 1" in hints(check_rectifying_rotation(wrong, verbose=False))


def test_rectifying_uses_t_as_baseline():
    def wrong(R, t):
        x = t / np.linalg.norm(t)
        y = np.cross([0.0, 0.0, 1.0], x)
        y /= np.linalg.norm(y)
        return np.stack([x, y, np.cross(x, y)])
    assert "C2 = -Rᵀt" in hints(check_rectifying_rotation(wrong, verbose=False))


def test_rectifying_columns_instead_of_rows():
    assert "rows" in hints(check_rectifying_rotation(lambda R, t: rectifying_reference(R, t).T, verbose=False))


def test_rectifying_y_up():
    def wrong(R, t):
        Rr = rectifying_reference(R, t)
        return np.stack([Rr[0], -Rr[1], -Rr[2]])
    assert "y points up" in hints(check_rectifying_rotation(wrong, verbose=False))


def test_rectifying_library_matches_reference():
    R = np.eye(3)
    t = np.array([-0.1, 0.01, 0.0])
    assert np.allclose(rectify_fusiello(np.eye(3), np.eye(3), R, t).R_rect, rectifying_reference(R, t))
