"""The plot helpers of notebooks 08 and 09 draw without error and return their axis."""
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from labutils.plotting.views import (  # noqa: E402
    plot_error_growth,
    plot_errors_per_view,
    plot_pyramid,
    plot_registration_order,
    plot_view_graph,
)


def test_helpers_draw_and_return_the_axis():
    fig, axs = plt.subplots(1, 5)
    x = np.random.default_rng(0).uniform([0, 0], [720, 576], (30, 2))
    assert plot_pyramid(axs[0], x, (720, 576), level=2) is axs[0]
    assert len(axs[0].patches) == len({(int(a // 180), int(b // 144)) for a, b in x})     # one patch per full cell
    assert plot_registration_order(axs[1], {"a": [0, 1, 2], "b": [0, 2, 1]}, 3) is axs[1]
    assert plot_error_growth(axs[2], {"a": ([3, 4], [0.5, 0.4])}) is axs[2]
    assert plot_view_graph(axs[3], [[0, 1], [1, 2]], 4, [1.0, 2.0], "err") is axs[3]
    assert plot_errors_per_view(axs[4], {"a": [0.1, np.nan, 0.3]}) is axs[4]
    plt.close(fig)
