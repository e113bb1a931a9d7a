"""The 3D plot helpers of labutils.plotting.common refuse arrays of the wrong shape instead of reshaping them into
garbage points or cameras."""
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from labutils.plotting.common import (  # noqa: E402
    camera_frusta,
    plot_cameras,
    plot_cameras_and_points,
    plot_points,
    show_mesh,
    show_reconstruction,
)

K = np.diag([100.0, 100.0, 1.0])
R = np.stack([np.eye(3)] * 4)
t = np.array([[0, 0, 5.0], [1, 0, 5], [np.nan] * 3, [0, 1, 5]])     # view 2 unregistered: skipped, not an error


def test_good_shapes_draw():
    X = np.random.default_rng(0).normal(size=(12, 3))
    X[3] = np.nan                                                        # NaN rows are skipped
    assert camera_frusta(R, t, K, (200, 100), 1.0).shape == (24, 2, 3)
    assert camera_frusta(np.eye(3), [0, 0, 5.0], K, (200, 100), 1.0).shape == (8, 2, 3)   # one camera
    assert [tr.type for tr in show_reconstruction(X, R=R, t=t).data] == ["scatter3d", "scatter3d"]
    fig = plt.figure()
    ax = fig.add_subplot(projection="3d")
    assert plot_cameras_and_points(ax, R[:2], t[:2], X) is ax
    assert plot_cameras(ax, np.eye(3), np.zeros(3)) is ax
    plt.close(fig)


def test_transposed_or_mismatched_arrays_are_refused():
    X = np.random.default_rng(0).normal(size=(12, 3))
    fig = plt.figure()
    ax = fig.add_subplot(projection="3d")
    for call, message in [
        (lambda: show_reconstruction(X.T), r"X must have shape \(N, 3\) .*got shape \(3, 12\) — transposed\? "
                                           "points are rows"),
        (lambda: show_reconstruction(X, R=R, t=t.T), r"t must have shape \(V, 3\) .*— transposed\?"),
        (lambda: show_reconstruction(X, R=R[:, :2], t=t), r"R must have shape \(V, 3, 3\) or \(3, 3\)"),
        (lambda: camera_frusta(R, t.T, K, (200, 100), 1.0), r"t must have shape \(V, 3\)"),
        (lambda: camera_frusta(R, t[:3], K, (200, 100), 1.0), "R has 4 rotations but t has 3 translations"),
        (lambda: camera_frusta(R.reshape(-1, 3), t, K, (200, 100), 1.0), r"R must have shape"),
        (lambda: plot_cameras_and_points(ax, R, t.T), r"t must have shape \(V, 3\)"),
        (lambda: plot_cameras_and_points(ax, X=X.T), "transposed\\? points are rows"),
        (lambda: plot_points(ax, X.T), "transposed\\? points are rows"),
        (lambda: plot_cameras(ax, R, t.ravel()), r"t must have shape \(V, 3\) or \(3,\)"),
        (lambda: show_reconstruction("points"), "X must be a numeric array"),
    ]:
        with pytest.raises(ValueError, match=message):
            call()
    plt.close(fig)


@pytest.mark.parametrize("static", [False, True])
def test_show_mesh_checks_the_mesh(static):
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    F = np.array([[0, 1, 2], [0, 1, 3]])
    for vertices, faces, message in [
        (V, [[0, 1, 4]], "faces hold vertex indices 0..3; got 0..4"),          # past the last vertex
        (V, F.astype(float), r"faces must be an \(F, 3\) integer array"),
        (V * [1, 1, np.nan], F, "vertices has non-finite coordinates"),
        (V.T, F, "transposed"),
    ]:
        with pytest.raises(ValueError, match=message):
            show_mesh(vertices, faces, static=static)
    with pytest.raises(ValueError, match="faces hold vertex indices"):
        show_reconstruction(V, mesh=(V, [[0, 1, 4]]), static=static)
    plt.close("all")


def test_interactive_views_carry_their_title_as_plotly_draws_it():
    """plotly.js 7 draws only ``layout.title.text``: a bare string title (kept as is by ``_validate=False``) is
    silently dropped in the browser."""
    X = np.random.default_rng(0).normal(size=(20, 3))
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    mesh = show_mesh(V, np.array([[0, 1, 2]]), title="the dinosaur")
    for fig in (show_reconstruction(X, title="the dinosaur"), mesh):
        assert fig.to_dict()["layout"]["title"] == {"text": "the dinosaur"}
    assert not show_reconstruction(X).to_dict()["layout"].get("title")
