"""Plots for dense stereo: disparity and depth maps, a pixel's score curve, what the left–right check removed
(a rectified pair with its rows: :func:`labutils.plotting.plot_rectified_pair`).

Each helper takes an ``ax`` and returns it; none calls ``plt.show()`` or changes global style.
"""
import numpy as np

__all__ = ["plot_disparity", "plot_score_curve", "plot_check_outcome"]


def plot_disparity(ax, disparity, vmin=None, vmax=None, cmap="turbo", title=None, colorbar=True, label="pixels"):
    """A disparity (or depth) map; pixels without a value (NaN) in light grey."""
    import matplotlib.pyplot as plt

    d = np.asarray(disparity, float)
    cm = plt.get_cmap(cmap).copy()
    cm.set_bad((0.85, 0.85, 0.85))
    im = ax.imshow(np.ma.masked_invalid(d), cmap=cm, vmin=vmin, vmax=vmax, interpolation="nearest")
    if colorbar:
        ax.figure.colorbar(im, ax=ax, fraction=0.035, pad=0.02, label=label)
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=9)
    return ax


def plot_score_curve(ax, disparities, scores, d_best=None, d_true=None, label=None, color="C0"):
    """A pixel's ZNCC over the disparities swept, with the sweep's choice and (when known) the truth."""
    ax.plot(disparities, scores, "o-", ms=3, color=color, label=label)
    if d_best is not None and np.isfinite(d_best):
        ax.axvline(d_best, color=color, ls="--", lw=1)
    if d_true is not None:
        ax.axvline(d_true, color="k", ls=":", lw=1, label="true disparity")
    ax.set_xlabel("disparity d (pixels)")
    ax.set_ylabel("ZNCC")
    ax.set_ylim(-1.05, 1.05)
    return ax


def plot_check_outcome(ax, valid, kept, occluded=None, title=None):
    """What the left–right check did: kept (grey), removed (red), no disparity at all (white); the true occlusions,
    when known, outlined in blue."""
    valid, kept = np.asarray(valid, bool), np.asarray(kept, bool)
    img = np.ones(valid.shape + (3,))
    img[valid & kept] = (0.6, 0.6, 0.6)
    img[valid & ~kept] = (0.9, 0.15, 0.1)
    ax.imshow(img, interpolation="nearest")
    if occluded is not None:
        ax.contour(np.asarray(occluded, float), levels=[0.5], colors=["royalblue"], linewidths=1.0)
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=9)
    return ax
