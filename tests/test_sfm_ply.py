"""``python -m labutils.sfm --ply POINTS.ply [--images DIR]``: oriented points, coloured from the images (the textured
snowman, whose colours are known), and each bad input refused on one line with nothing written."""
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from labutils.data.formats import write_tracks
from labutils.data.ply import read_model, validate_ply
from labutils.model.pointcloud import facing_fractions
from labutils.model.synthetic import make_textured_scene
from labutils.sfm.reconstruction import Reconstruction, align_reconstruction

ROOT = Path(__file__).resolve().parents[1]


def _cli(*args, cwd):
    env = dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1")
    return subprocess.run([sys.executable, "-W", "error::RuntimeWarning", "-m", "labutils.sfm", *map(str, args)],
                          cwd=cwd, capture_output=True, text=True, env=env, timeout=300)


@pytest.fixture(scope="module")
def snowman_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("snowman")
    s = make_textured_scene(12, rng=np.random.default_rng(0), image_size=(200, 150), f=260.0, noise=1.0)
    X, n = s.surface_points(600, rng=np.random.default_rng(1))
    vis = s.visibility(X, n)
    keep = vis.sum(0) >= 2
    X, n, vis = X[keep], n[keep], vis[:, keep]
    x = s.project(X, vis) + np.random.default_rng(2).normal(scale=0.2, size=(s.n_views, len(X), 2))
    write_tracks(d / "tracks.txt", x)
    (d / "K.txt").write_text("".join(" ".join(f"{v:.17g}" for v in row) + "\n" for row in s.K[0]))
    (d / "images").mkdir()
    for i, img in enumerate(s.images):
        cv2.imwrite(str(d / "images" / f"view{i:02d}.png"), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    return d, s, X, n, vis


def test_ply_with_images_has_colours_and_outward_normals(snowman_files):
    d, s, X, n, vis = snowman_files
    r = _cli("tracks.txt", "K.txt", "--out", "res.json", "--ply", "pts.ply", "--images", "images", "--quiet", cwd=d)
    assert r.returncode == 0, r.stderr
    assert validate_ply(d / "pts.ply").format == "binary_little_endian"
    m = read_model(d / "pts.ply")
    res = json.loads((d / "res.json").read_text())
    track = np.array([p["track"] for p in res["points"]])
    assert len(m.vertices) == len(track) > 0.9 * len(X)
    # colours: the median over the views of bilinear samples at the reprojected points (0.2 px off the true ones)
    err = np.abs(m.colors.astype(float) - s.colour(X[track], n[track]))
    assert np.median(err) < 4
    # normals: unit; after aligning the reconstruction to the true cameras they point out of the snowman
    assert np.allclose(np.linalg.norm(m.normals, axis=1), 1, atol=1e-6)
    R = np.array([c["R"] for c in res["cameras"]])
    t = np.array([c["t"] for c in res["cameras"]])
    inl = np.zeros((s.n_views, len(X)), bool)
    for p in res["points"]:
        inl[p["views"], p["track"]] = True
    rec = Reconstruction(R=R, t=t, registered=np.ones(s.n_views, bool), X=np.full((len(X), 3), np.nan),
                         inliers=inl, order=res["order"], K=s.K)
    rec.X[track] = m.vertices
    Ra, ta, _ = align_reconstruction(rec, s.R, s.t)
    Rsim = Ra[0].T @ R[0]                                       # the similarity's rotation (world of rec -> true)
    normals_true_frame = m.normals @ Rsim.T
    assert (np.einsum("ij,ij->i", normals_true_frame, n[track]) > 0).mean() >= 0.99
    assert facing_fractions(m.vertices, m.normals, R, t, inl[:, track])["any"] >= 0.99


def test_ply_ascii_without_images(snowman_files, tmp_path):
    d = snowman_files[0]
    r = _cli(d / "tracks.txt", d / "K.txt", "--out", "r.json", "--ply", "p.ply", "--ply-format", "ascii", "--quiet",
             cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    m = read_model(tmp_path / "p.ply")
    assert validate_ply(tmp_path / "p.ply").format == "ascii" and m.colors is None and m.normals is not None
    umask = os.umask(0)
    os.umask(umask)
    assert oct((tmp_path / "p.ply").stat().st_mode & 0o777) == oct(0o666 & ~umask)


def _one_line(r, *words):
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in r.stderr, r.stderr
    for w in words:
        assert w in lines[0], (w, lines[0])


def test_bad_images_are_refused_before_the_work(snowman_files, tmp_path):
    d = snowman_files[0]
    common = [d / "tracks.txt", d / "K.txt", "--out", "r.json", "--ply", "p.ply"]
    (tmp_path / "few").mkdir()
    cv2.imwrite(str(tmp_path / "few" / "a.png"), np.zeros((5, 5, 3), np.uint8))
    _one_line(_cli(*common, "--images", "few", cwd=tmp_path), "few", "1 images", "for 12 views")
    _one_line(_cli(*common, "--images", "nowhere", cwd=tmp_path), "nowhere", "not a folder")
    _one_line(_cli(d / "tracks.txt", d / "K.txt", "--out", "r.json", "--images", d / "images", cwd=tmp_path),
              "give --ply too")
    (tmp_path / "broken").mkdir()
    for i in range(12):
        (tmp_path / "broken" / f"v{i:02d}.png").write_bytes(b"not a png" if i == 7 else cv2.imencode(
            ".png", np.zeros((5, 5, 3), np.uint8))[1].tobytes())
    _one_line(_cli(*common, "--images", "broken", cwd=tmp_path), "v07.png", "cannot read")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken", "few"]          # nothing written
