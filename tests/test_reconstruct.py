"""labutils.reconstruct: EXIF focal lengths, self-calibration, shared intrinsics refined in BA, the capture check,
and ``python -m labutils.reconstruct`` on rendered photos with a known camera and lens (issue 23)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from labutils.core import relative_pose
from labutils.core.synthetic import make_scene
from labutils.reconstruct import (
    capture_check,
    focal_from_exif,
    focal_from_fundamentals,
    reconstruct_photos,
    refine_shared_intrinsics,
    render_photo_folder,
    sharpness,
)
from labutils.twoview import fundamental_from_pose

ROOT = Path(__file__).resolve().parents[1]


def _jpeg(path, size=(400, 300), **tags):
    exif = Image.Exif()
    ifd = {}
    names = dict(focal=37386, fpx=41486, funit=41488, f35=41989, width=40962, height=40963)
    for k, v in tags.items():
        ifd[names[k]] = v
    img = Image.new("RGB", size)
    if ifd:
        exif_ifd = exif.get_ifd(0x8769)
        exif_ifd.update(ifd)
    img.save(path, exif=exif)
    return path


def test_exif_focal_plane_35mm_and_the_stated_guess(tmp_path):
    # 4.0 mm at 1000 px/cm on a 4000-px-wide sensor, file 400 px wide: 4 mm * 100 px/mm * 400/4000 = 40 px
    g = focal_from_exif(_jpeg(tmp_path / "a.jpg", focal=4.0, fpx=1000.0, funit=3, width=4000, height=3000))
    assert g.source == "exif-focal-plane" and g.f_px == pytest.approx(40.0)
    # 35 mm equivalent 43.27 mm: the diagonal's length in pixels (500 for 400 x 300)
    g = focal_from_exif(_jpeg(tmp_path / "b.jpg", f35=43))
    assert g.source == "exif-35mm" and g.f_px == pytest.approx(43 * 500 / np.hypot(36, 24))
    g = focal_from_exif(_jpeg(tmp_path / "c.jpg"))
    assert g.source == "guess" and g.f_px == 480.0 and "guessed" in g.text
    (tmp_path / "d.jpg").write_bytes(b"not a jpeg")
    with pytest.raises(ValueError, match="d.jpg: cannot read"):
        focal_from_exif(tmp_path / "d.jpg")


def test_self_calibration_is_exact_without_noise_and_robust_to_a_wrong_pair():
    s = make_scene(60, 6, rng=np.random.default_rng(3))
    Fs = [fundamental_from_pose(s.K, s.K, *relative_pose(s.R[i], s.t[i], s.R[j], s.t[j]))
          for i in range(6) for j in range(i + 1, 6)]
    f, curve, sharp = focal_from_fundamentals(Fs, s.K[:2, 2], max(s.image_size))
    assert abs(f / s.K[0, 0] - 1) < 1e-6 and sharp < 0.05 and curve.shape == (120, 2)
    Fs[0] = np.random.default_rng(0).normal(size=(3, 3))            # one pair's F is garbage: the median ignores it
    f, _, _ = focal_from_fundamentals(Fs, s.K[:2, 2], max(s.image_size))
    assert abs(f / s.K[0, 0] - 1) < 1e-3
    with pytest.raises(ValueError, match=r"Fs must have shape \(P, 3, 3\)"):
        focal_from_fundamentals(np.eye(3), s.K[:2, 2], 640)


def _distorted_scene(seed, k=(-0.15, 0.05), noise_px=0.5, f_start=1.1):
    rng = np.random.default_rng(seed)
    s = make_scene(400, 12, layout="turntable", noise_px=0, rng=rng)
    f, c = s.K[0, 0], s.K[:2, 2]
    Xc = np.einsum("vij,tj->vti", s.R, s.X) + s.t[:, None]
    xn = Xc[..., :2] / Xc[..., 2:3]
    r2 = np.sum(xn ** 2, axis=-1, keepdims=True)
    x = f * xn * (1 + k[0] * r2 + k[1] * r2 ** 2) + c + rng.normal(0, noise_px, xn.shape)
    vis = np.isfinite(s.tracks[..., 0])
    x[~vis] = np.nan
    K0 = s.K.copy()
    K0[0, 0] = K0[1, 1] = f * f_start
    R0, t0 = s.R, s.t + rng.normal(0, 0.01, s.t.shape)
    return s, x, vis, K0, R0, t0, s.X + rng.normal(0, 0.01, s.X.shape)


@pytest.mark.parametrize("seed", [0, 1])
def test_shared_focal_and_distortion_recovered_within_their_standard_deviations(seed):
    s, x, vis, K0, R0, t0, X0 = _distorted_scene(seed)
    r = refine_shared_intrinsics(x, R0, t0, X0, vis, K0)
    f = s.K[0, 0]
    assert r.success and r.rms_px[1] < 0.6 < r.rms_px[0]                    # from 38 px to the noise
    # 3 sd (a Gaussian's 99.7 %): an estimate that ignores the distortion is 4-5 % (> 3 sd) off
    assert abs(r.K[0, 0] - f) < 3 * r.f_sd and r.f_sd < 0.03 * f
    assert abs(r.dist[0] + 0.15) < 3 * r.k_sd[0] and abs(r.dist[1] - 0.05) < 3 * r.k_sd[1]
    pinhole = refine_shared_intrinsics(x, R0, t0, X0, vis, K0, refine_distortion=False)
    assert np.all(pinhole.dist == 0) and pinhole.rms_px[1] > r.rms_px[1]


def test_the_prior_holds_the_focal_length_where_the_geometry_cannot():
    # two views of a distant, shallow scene: f and the depth trade off (nearly affine); the prior keeps f near its
    # centre instead of wandering
    rng = np.random.default_rng(5)
    s = make_scene(200, 2, noise_px=1.0, rng=rng)
    x, vis = s.tracks, np.isfinite(s.tracks[..., 0])
    r = refine_shared_intrinsics(x, s.R, s.t, s.X, vis, s.K, f_prior=(s.K[0, 0], 0.05), refine_distortion=False)
    assert abs(np.log(r.K[0, 0] / s.K[0, 0])) < 3 * 0.05


def test_bad_input_is_refused():
    s, x, vis, K0, R0, t0, X0 = _distorted_scene(0)
    with pytest.raises(ValueError, match="tracks must have shape"):
        refine_shared_intrinsics(x[..., 0], R0, t0, X0, vis, K0)
    with pytest.raises(ValueError, match="inliers must be"):
        refine_shared_intrinsics(x, R0, t0, X0, vis.astype(int), K0)
    K = K0.copy()
    K[1, 1] *= 1.1
    with pytest.raises(ValueError, match="square pixels"):
        refine_shared_intrinsics(x, R0, t0, X0, vis, K)


def test_capture_check_names_blur_few_features_and_views_to_reshoot():
    rng = np.random.default_rng(0)
    sharp = (rng.random((120, 160)) * 255).astype(np.uint8)
    blurred = cv2.GaussianBlur(sharp, (0, 0), 4)
    names = [f"{k}.jpg" for k in range(6)]
    inl = {(i, j): (200 if j - i == 1 and j <= 3 else 0) for i in range(6) for j in range(i + 1, 6)}
    inl[(4, 5)] = 150                                # views 4-5 hang together, but not with 0-3
    r = capture_check(names, [sharp] * 5 + [blurred], [900, 900, 900, 40, 900, 900], inl)
    assert r.component.tolist() == [0, 0, 0, 0, 1, 1] and not r.ok
    text = "\n".join(r.problems)
    assert "view 5 (5.jpg) looks blurred" in text and "view 3 (3.jpg) has few features" in text
    assert "views 4-5 share too little with the rest" in text and "between it and view 3" in text
    assert sharpness(blurred) < sharpness(sharp) / 3


def _render_folder(folder, k1):
    return render_photo_folder(folder, rng=np.random.default_rng(1), dist=(k1, 0.0))


def _run(*args):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "labutils.reconstruct", *map(str, args)], capture_output=True,
                          text=True, env=env, cwd=ROOT)


def test_rendered_photos_with_a_known_lens_give_the_camera_back(tmp_path):
    """Six rendered views of a textured box corner, distorted with k1 = -0.2, no calibration given: every view
    registers, f within 2 % (the issue's bar), and k1's sign and size are recovered."""
    photos = tmp_path / "photos"
    photos.mkdir()
    s = _render_folder(photos, -0.2)
    out, ply, report = tmp_path / "r.json", tmp_path / "m.ply", tmp_path / "report.md"
    p = _run(photos, "--out", out, "--ply", ply, "--report", report, "--quiet")
    assert p.returncode == 0, p.stderr
    res = json.loads(out.read_text())
    assert res["images"] == [f"{i:03d}.png" for i in range(6)] and all(c is not None for c in res["cameras"])
    cam = res["cameras"][0]
    assert abs(cam["K"][0][0] / s.K[0, 0] - 1) < 0.02
    # f, k1 and k2 trade off over an image's radii: judge the camera by where it puts a ray at angle atan(r) from
    # the axis, ρ(r) = f r (1 + k1 r² + k2 r⁴) pixels from the centre, against the truth's f r (1 - 0.2 r²) (the lens
    # moves the corners by 25 px): within 2 % of the radius everywhere (the focal length's bar), and the lens is
    # found: a pinhole at the same f would be more than three times further off in the corners
    f, (k1, k2) = cam["K"][0][0], cam["dist"]
    r = np.linspace(0.05, np.hypot(*(np.array(s.image_size) / 2)) / s.K[0, 0], 50)
    rho, rho_true = f * r * (1 + k1 * r ** 2 + k2 * r ** 4), s.K[0, 0] * r * (1 - 0.2 * r ** 2)
    assert np.max(np.abs(rho / rho_true - 1)) < 0.02
    assert abs(f * r[-1] - rho_true[-1]) > 3 * abs(rho[-1] - rho_true[-1])
    R = np.array([c["R"] for c in res["cameras"]])
    assert np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3), atol=1e-9)
    rel = [relative_pose(R[0], np.zeros(3), R[k], np.zeros(3))[0] for k in range(6)]
    true = [relative_pose(s.R[0], np.zeros(3), s.R[k], np.zeros(3))[0] for k in range(6)]
    angles = [np.degrees(np.arccos(np.clip((np.trace(a.T @ b) - 1) / 2, -1, 1))) for a, b in zip(rel, true)]
    assert max(angles) < 0.5
    assert ply.read_bytes().startswith(b"ply") and "## Capture check" in report.read_text()
    assert len(res["points"]) == len(res["colors"]) > 100


def test_a_folder_that_cannot_work_says_why_and_writes_nothing(tmp_path):
    photos = tmp_path / "photos"
    photos.mkdir()
    rng = np.random.default_rng(0)
    for k in range(3):                                    # three unrelated noise images: nothing matches
        cv2.imwrite(str(photos / f"{k}.png"), (rng.random((240, 320)) * 255).astype(np.uint8))
    out = tmp_path / "r.json"
    p = _run(photos, "--out", out, "--quiet")
    assert p.returncode == 2 and not out.exists()
    assert p.stderr.startswith("error:") and "cannot reconstruct" in p.stderr and "share" in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1


def test_an_output_that_is_an_input_is_refused_before_any_work(tmp_path):
    photos = tmp_path / "photos"
    photos.mkdir()
    for k in range(2):
        cv2.imwrite(str(photos / f"{k}.png"), np.zeros((32, 32), np.uint8))
    before = (photos / "0.png").read_bytes()
    p = _run(photos, "--out", photos / "0.png")
    assert p.returncode == 2 and "--out is a photo" in p.stderr and (photos / "0.png").read_bytes() == before
    p = _run(photos, "--out", tmp_path / "a.json", "--report", tmp_path / "a.json")
    assert p.returncode == 2 and "--report and --out name the same file" in p.stderr
    p = _run(photos, "--out", tmp_path / "a.json", "--seed", "-1")
    assert p.returncode == 2 and "--seed: must be a non-negative integer" in p.stderr


@pytest.mark.parametrize("call, message", [
    (lambda s, vis: refine_shared_intrinsics(s.tracks + 0j, s.R, s.t, s.X, vis, s.K), "tracks must be real"),
    (lambda s, vis: refine_shared_intrinsics(s.tracks, s.R, s.t, s.X, vis, s.K, f_prior=(800,)), "f_prior must be"),
    (lambda s, vis: refine_shared_intrinsics(s.tracks, s.R, s.t, s.X, vis, s.K, max_points=True), "max_points"),
    (lambda s, vis: focal_from_fundamentals(np.diag([1, 1, 0.0])[None], [1, 1], 100, n_grid=True), "n_grid"),
    (lambda s, vis: focal_from_fundamentals(np.zeros((1, 3, 3)), [1, 1], 100), "all-zero"),
    (lambda s, vis: focal_from_fundamentals(np.diag([1, 1, 0.0])[None], [1, 1], 100, span=(5, 0.2)), "span"),
    (lambda s, vis: capture_check(["a", "b"], [np.zeros((8, 8), np.uint8)] * 2, [True, 3], {(0, 1): 30}),
     r"n_features\[0\]"),
    (lambda s, vis: capture_check(["a", "b"], [np.zeros((8, 8), np.uint8)] * 2, [5, 3], {(0, 1): -30}),
     "pair_inliers"),
    (lambda s, vis: sharpness(np.full((8, 8), np.nan)), "gray must be a finite"),
    (lambda s, vis: reconstruct_photos(["a.jpg", "b.jpg"], rng=np.random.default_rng(0), dist=[0.1, 0.0]),
     "dist goes with K"),
    (lambda s, vis: reconstruct_photos(["a.jpg", "b.jpg"], rng=np.random.default_rng(0), max_size=0), "max_size"),
])
def test_bad_input_to_the_pieces_is_refused_by_name(call, message):
    s = make_scene(40, 3, noise_px=0.5, rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match=message):
        call(s, np.isfinite(s.tracks[..., 0]))
