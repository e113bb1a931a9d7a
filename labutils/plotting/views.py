"""Plot helpers of notebooks 08 and 09 (next-best-view, global SfM): each takes an ``ax`` and returns it."""
import matplotlib.patches as mpatches
import matplotlib.pyplot as plt
import numpy as np

from .common import image_frame


def plot_pyramid(ax, x, extent, level=3, image=None, image_size=None, color="C1", fill="C0", size=6):
    """Points ``x`` (N, 2) on an image with the ``K × K`` cells of one pyramid level (``K = 2^level``), the full
    ones shaded (the visibility pyramid of :func:`labutils.sfm.pyramid_score`)."""
    x = np.asarray(x, float).reshape(-1, 2)
    e = np.asarray(extent, float)
    x0, y0, x1, y1 = (0.0, 0.0, e[0], e[1]) if e.shape == (2,) else e
    image_frame(ax, image, image_size if image_size is not None else (x1, y1))
    n = 2 ** level
    w, h = (x1 - x0) / n, (y1 - y0) / n
    if len(x):
        cx = np.clip(np.floor((x[:, 0] - x0) / w), 0, n - 1).astype(int)
        cy = np.clip(np.floor((x[:, 1] - y0) / h), 0, n - 1).astype(int)
        for i, j in set(zip(cx.tolist(), cy.tolist())):
            ax.add_patch(mpatches.Rectangle((x0 + i * w, y0 + j * h), w, h, color=fill, alpha=0.25, lw=0))
    for k in range(n + 1):
        ax.plot([x0 + k * w] * 2, [y0, y1], color="0.6", lw=0.5)
        ax.plot([x0, x1], [y0 + k * h] * 2, color="0.6", lw=0.5)
    ax.scatter(x[:, 0], x[:, 1], s=size, color=color, zorder=3)
    return ax


def plot_registration_order(ax, orders, n_views, markers="osd^v"):
    """For each strategy (``{name: order}``), the view registered at each step: step on x, view on y."""
    for k, (name, order) in enumerate(orders.items()):
        ax.plot(np.arange(len(order)), order, marker=markers[k % len(markers)], ms=4, lw=1, label=name)
    ax.set_xlabel("registration step (0, 1: the initial pair)")
    ax.set_ylabel("view")
    ax.set_ylim(-1, n_views)
    ax.legend(fontsize=8)
    return ax


def plot_error_growth(ax, curves, ylabel="mean rotation error (°)"):
    """``{name: (n_registered (k,), error (k,))}`` as curves: how the error evolves as views are added."""
    for name, (n, err) in curves.items():
        ax.plot(n, err, marker=".", lw=1, label=name)
    ax.set_xlabel("views registered")
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=8)
    return ax


def plot_view_graph(ax, pairs, n_views, values=None, label="", cmap="viridis", vmax=None):
    """The views on a circle (in index order, as on a turntable) and one chord per measured pair, coloured by
    ``values`` (e.g. each edge's rotation error)."""
    a = 2 * np.pi * np.arange(n_views) / n_views
    p = np.stack([np.cos(a), np.sin(a)], axis=1)
    pairs = np.asarray(pairs, int).reshape(-1, 2)
    vals = np.zeros(len(pairs)) if values is None else np.asarray(values, float)
    norm = plt.Normalize(0, vmax if vmax is not None else max(np.nanmax(vals), 1e-12))
    cm = plt.get_cmap(cmap)
    for (i, j), v in sorted(zip(pairs.tolist(), vals), key=lambda e: e[1]):
        ax.plot(*p[[i, j]].T, color=cm(norm(v)), lw=1.0)
    ax.scatter(*p.T, s=30, color="k", zorder=3)
    for v in range(0, n_views, max(1, n_views // 12)):
        ax.annotate(str(v), 1.12 * p[v], ha="center", va="center", fontsize=7)
    if values is not None:
        plt.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cm), ax=ax, label=label, shrink=0.8)
    ax.set_xlim(-1.25, 1.25)
    ax.set_ylim(-1.25, 1.25)
    ax.set_aspect("equal")
    ax.axis("off")
    return ax


def plot_errors_per_view(ax, errors, ylabel="rotation error (°)", markers="o.sd^v"):
    """``{name: (V,) per-view errors}`` against the view index (NaN for views without an estimate)."""
    for k, (name, err) in enumerate(errors.items()):
        err = np.asarray(err, float)
        ax.plot(np.arange(len(err)), err, marker=markers[k % len(markers)], ms=3, lw=1, label=name)
    ax.set_xlabel("view (around the turntable)")
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=8)
    return ax


def plot_self_calibration(ax, curve, f=None, f_true=None):
    """The self-calibration's criterion against the focal length (log x), with the estimate and, if known, the truth.

    ``curve`` is ``(n, 2)``: ``(f, median asymmetry of E = Kᵀ F K)`` (``PhotoReconstruction.self_calibration``).
    """
    c = np.asarray(curve, float)
    if c.ndim != 2 or c.shape[1] != 2 or len(c) < 2:
        raise ValueError(f"curve must have shape (n, 2) with n >= 2; got shape {c.shape}")
    ax.semilogx(c[:, 0], c[:, 1], "k-", lw=1)
    if f is not None:
        ax.axvline(f, color="C0", label=f"estimate {f:.0f} px")
    if f_true is not None:
        ax.axvline(f_true, color="C3", ls="--", label=f"given K {f_true:.0f} px")
    ax.set(xlabel="focal length f (px)", ylabel="median (σ1 − σ2) / (σ1 + σ2) of E")
    if f is not None or f_true is not None:
        ax.legend()
    return ax
