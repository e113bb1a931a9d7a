"""Plot helpers for matches and tracks (notebook 07). Each takes an ``ax`` and returns it; none calls ``plt.show()``."""
import numpy as np
from numpy.typing import ArrayLike


def side_by_side(image1: ArrayLike, image2: ArrayLike) -> tuple[np.ndarray, int]:
    """The two images next to each other (grey or RGB, different heights allowed), and the x offset of image 2.

    >>> canvas, dx = side_by_side(np.zeros((4, 5), np.uint8), np.zeros((3, 2, 3), np.uint8))
    >>> canvas.shape, dx
    ((4, 7, 3), 5)
    """
    ims = []
    for im in (image1, image2):
        im = np.asarray(im)
        ims.append(np.repeat(im[..., None], 3, axis=2) if im.ndim == 2 else im[..., :3])
    h = max(im.shape[0] for im in ims)
    canvas = np.zeros((h, ims[0].shape[1] + ims[1].shape[1], 3), ims[0].dtype)
    canvas[:ims[0].shape[0], :ims[0].shape[1]] = ims[0]
    canvas[:ims[1].shape[0], ims[0].shape[1]:] = ims[1]
    return canvas, ims[0].shape[1]


def plot_match_lines(ax, image1: ArrayLike, image2: ArrayLike, x1: ArrayLike, x2: ArrayLike,
                     good: ArrayLike | None = None, max_lines: int = 200, lw: float = 0.6,
                     labels: tuple[str, str] = ("kept", "rejected")):
    """Matches as lines between two images shown side by side: ``good`` in green, the others in red.

    Parameters
    ----------
    ax : matplotlib axis
    image1, image2 : arrays
    x1, x2 : (N, 2) array_like
        Matched pixels in image 1 and image 2.
    good : (N,) bool array_like, optional
        Which matches to draw green (all when None).
    max_lines : int
        Draw at most this many of each colour (evenly spread over the list, so the picture is deterministic).
    labels : (str, str)
        Legend names of the green and the red lines.
    """
    x1, x2 = np.asarray(x1, float).reshape(-1, 2), np.asarray(x2, float).reshape(-1, 2)
    good = np.ones(len(x1), bool) if good is None else np.asarray(good, bool)
    canvas, dx = side_by_side(image1, image2)
    ax.imshow(canvas, cmap="gray")
    for mask, color, label in ((good, "lime", labels[0]), (~good, "red", labels[1])):
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            continue
        idx = idx[np.linspace(0, idx.size - 1, min(max_lines, idx.size)).astype(int)]
        xs = np.stack([x1[idx, 0], x2[idx, 0] + dx])
        ys = np.stack([x1[idx, 1], x2[idx, 1]])
        ax.plot(xs, ys, color=color, lw=lw, alpha=0.8)
        ax.plot([], [], color=color, label=f"{label} ({mask.sum()})")
    ax.set_axis_off()
    return ax


def plot_track_lengths(ax, length_counts: dict, width: float = 0.8):
    """Histogram of track lengths for several track sets side by side (log scale).

    Parameters
    ----------
    length_counts : dict
        ``{name: counts}`` with ``counts[L]`` = tracks seen in exactly L views (``track_statistics``).
    """
    names = list(length_counts)
    L = max(len(c) for c in length_counts.values())
    w = width / max(len(names), 1)
    for k, name in enumerate(names):
        c = np.zeros(L)
        c[:len(length_counts[name])] = length_counts[name]
        x = np.arange(2, L)
        ax.bar(x + (k - (len(names) - 1) / 2) * w, c[2:], w, label=name)
    longest = max(int(np.flatnonzero(np.asarray(c))[-1]) if np.any(c) else 2 for c in length_counts.values())
    ax.set_xlim(1.4, longest + 0.6)
    ax.set_yscale("log")
    ax.set_xlabel("views per track")
    ax.set_ylabel("tracks")
    return ax
