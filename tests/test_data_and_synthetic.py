import numpy as np
import pytest

import labutils
from labutils.core.geometry import depths, project
from labutils.core.scene import nan_tracks, observations, tracks_from_observations
from labutils.core.synthetic import make_scene
from labutils.data.paths import find_data


def test_missing_data_names_files_and_source(monkeypatch):
    monkeypatch.setenv("LABUTILS_DATA", "none")
    assert labutils.data_dirs() == []
    with pytest.raises(labutils.DataNotFoundError) as err:
        labutils.load_dino()
    assert "BAdino2.mat" in str(err.value) and "viff.000.png" in str(err.value) and "robots.ox.ac.uk" in str(err.value)
    assert "python -m labutils.data fetch dino" in str(err.value) and "LABUTILS_DATA=none" in str(err.value)


def test_missing_data_names_each_folder_searched(tmp_path, monkeypatch):
    monkeypatch.setenv("LABUTILS_DATA", str(tmp_path / "mine"))
    with pytest.raises(labutils.DataNotFoundError) as err:
        labutils.find_data("nothing-here/file.txt")
    lines = str(err.value).splitlines()
    assert str(tmp_path / "mine") in lines[1] and "does not exist" in lines[1]      # the order of the data path
    assert "data" in lines[2] and "fetch nothing-here" in str(err.value)


def test_fallback_is_synthetic_and_says_so(monkeypatch, capsys):
    monkeypatch.setenv("LABUTILS_DATA", "none")
    scene = labutils.load_scene(rng=np.random.default_rng(0))
    assert scene.source == "synthetic"
    assert "SYNTHETIC" in capsys.readouterr().out


def test_data_path_order(tmp_path, monkeypatch):
    (tmp_path / "dino").mkdir()
    (tmp_path / "dino" / "marker.txt").write_text("x")
    monkeypatch.setenv("LABUTILS_DATA", str(tmp_path))
    assert labutils.data_dirs()[0] == tmp_path
    assert find_data("dino/marker.txt") == tmp_path / "dino" / "marker.txt"


def test_observations_round_trip(rng):
    x = rng.normal(size=(3, 5, 2))
    x[rng.random((3, 5)) < 0.4] = np.nan
    cam, pt, p2 = observations(x)
    assert np.all(np.isfinite(p2))
    back = tracks_from_observations(cam, pt, p2, 3, 5)
    assert np.array_equal(np.isnan(back), np.isnan(x)) and np.allclose(back[~np.isnan(x)], x[~np.isnan(x)])
    assert np.isnan(nan_tracks(np.array([[[-1.0, -1.0]]]))).all()


@pytest.mark.parametrize("layout,views", [("general", 2), ("turntable", 36), ("forward", 2)])
def test_synthetic_truth_is_consistent(layout, views, rng):
    s = make_scene(300, views, layout=layout, noise_px=0.5, outlier_ratio=0.1, rng=rng)
    for i in range(views):
        vis = s.visible[i]
        assert np.allclose(project(s.P[i], s.X[vis]), s.x_true[i, vis], atol=1e-9)
        assert np.all(depths(s.R[i], s.t[i], s.X[vis]) > 0)
    assert np.array_equal(np.isnan(s.x_meas), np.isnan(s.x_true))
    clean = s.visible & ~s.outliers
    assert 0.4 < np.std(s.x_meas[clean] - s.x_true[clean]) < 0.6
    assert 0.05 < s.outliers[s.visible].mean() < 0.15


def test_synthetic_is_deterministic_and_needs_rng():
    a = make_scene(50, 3, rng=np.random.default_rng(7))
    b = make_scene(50, 3, rng=np.random.default_rng(7))
    assert np.array_equal(a.x_meas, b.x_meas, equal_nan=True)
    with pytest.raises(TypeError, match="rng"):              # required, keyword-only
        make_scene(50, 3)
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator"):
        make_scene(50, 3, rng=None)


def test_dino_conventions(dino):
    assert dino.R.shape == (36, 3, 3) and dino.X.shape == (676, 3) and dino.tracks.shape == (36, 4983, 2)
    assert np.isfinite(dino.tracks[..., 0]).sum() == 16432
    assert np.allclose(np.linalg.det(dino.R), 1)
    for i in range(36):
        vis = dino.visible[i]
        assert np.all(depths(dino.R[i], dino.t[i], dino.X[vis]) > 0), "the mirror flip must put points in front"
        assert np.abs(project(dino.P[i], dino.X[vis]) - dino.x_true[i, vis]).max() < 1e-9
    assert np.allclose(np.linalg.norm(dino.C[:, :2], axis=1), 1, atol=1e-3) and np.abs(dino.C[:, 2]).max() < 1e-9
    assert not np.any(dino.tracks == -1) and not np.any(dino.x_meas == -1)
    err = np.linalg.norm(dino.x_meas - dino.x_true, axis=-1)[dino.visible]
    assert 0.8 < np.median(err) < 1.3
