"""One generic adaptive RANSAC loop, reused by the fundamental matrix and by PnP (H&Z Sec. 4.7.1, Alg. 4.5)."""
from collections.abc import Callable

import numpy as np

from .validation import as_count, as_fraction, as_positive, as_probability_open, as_rng


def ransac_iterations(inlier_ratio: float, sample_size: int, confidence: float) -> int:
    """Trials needed to draw one all-inlier sample with probability ``confidence`` (H&Z eq. 4.18).

    With no inliers (``inlier_ratio ** sample_size == 0``) no number of trials is enough: the result is then the
    largest int64, so that a RANSAC loop runs on to its ``max_iter``.

    >>> ransac_iterations(0.5, 8, 0.99)
    1177
    >>> ransac_iterations(0.5, 8, 1.0)
    Traceback (most recent call last):
    ...
    ValueError: confidence must be strictly between 0 and 1; got 1.0
    """
    w = as_fraction(inlier_ratio, "inlier_ratio", closed=True) ** as_count(sample_size, "sample_size", 1)
    confidence = as_probability_open(confidence, "confidence")
    if w <= 0.0:
        return np.iinfo(np.int64).max
    if w >= 1.0:
        return 1
    return int(np.ceil(np.log(1 - confidence) / np.log1p(-w)))


def ransac(n_data: int, sample_size: int, fit: Callable, errors: Callable, threshold: float, *,
           rng: np.random.Generator, confidence: float = 0.999, max_iter: int = 10000, min_iter: int = 1) -> tuple:
    """Adaptive RANSAC: sample, fit, score by inlier count, stop when ``confidence`` is reached.

    Parameters
    ----------
    n_data : int
        Number of data items (correspondences).
    sample_size : int
        Items per minimal sample.
    fit : callable
        ``fit(idx)`` gets the sampled indices and returns a list of candidate models (empty when
        the sample is degenerate; a minimal solver may return several).
    errors : callable
        ``errors(model)`` returns an ``(n_data,)`` array of errors (NaN or inf counts as an outlier).
    threshold : float
        An item is an inlier when its error is below ``threshold`` (in the errors' unit: pixels for F and PnP).
    rng : numpy.random.Generator
    confidence : float
        Probability that at least one sample was all inliers when the loop stops.
    max_iter, min_iter : int

    Returns
    -------
    model : object
        The candidate with the most inliers (ties broken by the smaller sum of inlier errors).
    inliers : (n_data,) bool ndarray
    n_iter : int
        Samples drawn.

    Raises
    ------
    ValueError
        Fewer data than ``sample_size``, no ``rng``, or no sample gave a model.
    """
    as_rng(rng)
    n_data, sample_size = as_count(n_data, "n_data", 0), as_count(sample_size, "sample_size", 1)
    threshold = as_positive(threshold, "threshold")
    confidence = as_probability_open(confidence, "confidence")
    max_iter, min_iter = as_count(max_iter, "max_iter", 1), as_count(min_iter, "min_iter", 1)
    if n_data < sample_size:
        raise ValueError(f"RANSAC needs at least {sample_size} data items; got {n_data}")
    best, best_inliers, best_key = None, np.zeros(n_data, bool), (-1, -np.inf)
    needed, it = max_iter, 0
    while it < min(needed, max_iter) or it < min_iter:
        it += 1
        idx = rng.choice(n_data, sample_size, replace=False)
        for model in fit(idx):
            e = np.asarray(errors(model), float)
            inl = np.isfinite(e) & (e < threshold)
            key = (int(inl.sum()), -float(e[inl].sum()))
            if key > best_key:
                best, best_inliers, best_key = model, inl, key
                needed = ransac_iterations(key[0] / n_data, sample_size, confidence)
    if best is None:
        raise ValueError(f"RANSAC found no model in {it} samples: every sample was degenerate")
    return best, best_inliers, it
