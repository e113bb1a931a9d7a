"""One generic adaptive RANSAC loop, reused by the fundamental matrix and by PnP (H&Z Sec. 4.7.1, Alg. 4.5).

Two things the bare loop does not say, and :func:`ransac` does:

- whether it stopped because it reached its ``confidence`` (``converged``), or because it ran out of
  samples (``max_iter``): a search that stops at ``max_iter`` has not found a sample free of outliers
  with the asked probability, and its best model may be the best of many wrong ones;
- whether its best model is better than chance (an a-contrario test, Moisan & Stival 2004, "A
  probabilistic criterion to detect rigid point matches", the ORSA of Moisan, Moulon & Monasse 2012).
  Under the null hypothesis the data are unrelated (e.g. pixels independent of the points): a model
  fitted to a minimal sample then counts each of the other ``n - s`` items as an inlier with some
  probability ``p`` (the fraction of the image, or of the image pairs, that the threshold accepts: the
  caller's ``chance``), independently, so its extra inliers are binomial ``B(n - s, p)``. Having tried
  ``M`` models, the probability that one of them reaches ``k`` inliers by chance is at most
  ``M · P(B(n - s, p) >= k - s)`` (a union bound; the "number of false alarms" of a-contrario
  detection), reported as ``p_chance`` (capped at 1). A model with ``p_chance > max_p_chance`` is
  refused: ``ValueError``. (``M`` counts the models actually scored, not ``max_iter``; a data-dependent
  stop can at worst inflate the false-acceptance rate by the harmonic sum ``Σ 1/m ≈ ln M``, a factor
  below 10 for ``M <= 10⁴``.) The default bar, 0.05, was set by measurement: on pure noise (PnP and F,
  N = 12-200, thresholds 1-12 px) ``p_chance`` was at least 0.3 in every run, while valid problems (0.3-4 px
  of noise, up to 50 % outliers, N >= 40) stayed below 0.02; an F from N = 20 with half outliers (three
  checks beyond its sample of 7) is refused: there the evidence really is that thin.
"""
from collections.abc import Callable

import numpy as np
import scipy.special

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


def chance_probability(n_inliers: int, n_data: int, sample_size: int, chance: float, n_models: int) -> float:
    """Bound on the probability that one of ``n_models`` models fitted to unrelated data gets ``n_inliers``.

    ``min(1, n_models · P(B(n_data - sample_size, chance) >= n_inliers - sample_size))``: the items of
    the minimal sample are inliers by construction, each other item is one with probability ``chance``
    (module docstring).

    >>> float(chance_probability(3, 10, 2, 0.5, 1))        # P(B(8, 1/2) >= 1) = 1 - 2⁻⁸
    0.99609375
    >>> bool(chance_probability(40, 40, 3, 1e-4, 1000) < 1e-100)
    True
    """
    m = n_inliers - sample_size
    if m <= 0:
        return 1.0
    tail = scipy.special.bdtrc(m - 1, n_data - sample_size, min(max(float(chance), 0.0), 1.0))   # P(B >= m)
    return float(min(1.0, n_models * tail))


class RansacResult(tuple):
    """What :func:`ransac` returns: the triple ``(model, inliers, n_iter)`` (it unpacks as one) and more.

    Attributes
    ----------
    model, inliers, n_iter
        The three items: best model, its ``(n_data,)`` bool inlier mask, samples drawn.
    n_models : int
        Candidate models scored (a sample may give several, or none).
    n_needed : int
        Samples needed for ``confidence`` at the best model's inlier ratio (H&Z eq. 4.18).
    converged : bool
        True when the loop stopped because it reached ``confidence`` (``n_iter >= n_needed``), False
        when it stopped at ``max_iter`` first.
    p_chance : float
        Bound on the probability that unrelated data give a model this good in ``n_models`` tries (module
        docstring); NaN when no ``chance`` was given.
    """

    def __new__(cls, model, inliers, n_iter, *, n_models, n_needed, converged, p_chance):
        self = super().__new__(cls, (model, inliers, n_iter))
        self.n_models, self.n_needed, self.converged, self.p_chance = n_models, n_needed, converged, p_chance
        return self

    model = property(lambda self: self[0])
    inliers = property(lambda self: self[1])
    n_iter = property(lambda self: self[2])

    def text(self):
        """One line: inliers, samples, whether the confidence was reached, the chance bound."""
        stop = "reached its confidence" if self.converged else f"stopped at max_iter (needed {self.n_needed})"
        return (f"{int(self.inliers.sum())}/{len(self.inliers)} inliers after {self.n_iter} samples "
                f"({self.n_models} models), {stop}, p_chance {self.p_chance:.2g}")


def ransac(n_data: int, sample_size: int, fit: Callable, errors: Callable, threshold: float, *,
           rng: np.random.Generator, confidence: float = 0.999, max_iter: int = 10000, min_iter: int = 1,
           chance=None, max_p_chance: float = 0.05) -> RansacResult:
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
    chance : float or callable, optional
        Probability that an item unrelated to a model is its inlier by chance, or ``chance(model)`` giving
        it for the best model. With it the best model must pass the a-contrario test (module docstring).
    max_p_chance : float
        Refuse the best model when its ``p_chance`` exceeds this.

    Returns
    -------
    RansacResult
        Unpacks as ``model, inliers, n_iter``: the candidate with the most inliers (ties broken by the
        smaller sum of inlier errors), its inlier mask, the samples drawn; also ``.converged``,
        ``.p_chance``, ``.n_models``, ``.n_needed``.

    Raises
    ------
    ValueError
        Fewer data than ``sample_size``, no ``rng``, no sample gave a model, or (with ``chance``) the best
        model is no better than chance.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> pts = np.c_[np.arange(20.), 2 * np.arange(20.) + 1]; pts[::4, 1] += 30      # a line, 5 outliers
    >>> fit = lambda i: [np.polyfit(*pts[i].T, 1)]
    >>> err = lambda m: np.abs(np.polyval(m, pts[:, 0]) - pts[:, 1])
    >>> res = ransac(20, 2, fit, err, 0.5, rng=rng, chance=0.02)
    >>> int(res.inliers.sum()), res.converged, bool(res.p_chance < 1e-9)
    (15, True, True)
    >>> noise = rng.uniform(0, 40, (20, 2))
    >>> ransac(20, 2, lambda i: [np.polyfit(*noise[i].T, 1)], lambda m: np.abs(np.polyval(m, noise[:, 0])
    ...        - noise[:, 1]), 0.5, rng=rng, chance=0.05, max_iter=200)       # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: RANSAC's best model is no better than chance: ...
    """
    as_rng(rng)
    n_data, sample_size = as_count(n_data, "n_data", 0), as_count(sample_size, "sample_size", 1)
    threshold = as_positive(threshold, "threshold")
    confidence = as_probability_open(confidence, "confidence")
    max_iter, min_iter = as_count(max_iter, "max_iter", 1), as_count(min_iter, "min_iter", 1)
    if n_data < sample_size:
        raise ValueError(f"RANSAC needs at least {sample_size} data items; got {n_data}")
    max_p_chance = as_probability_open(max_p_chance, "max_p_chance")
    best, best_inliers, best_key = None, np.zeros(n_data, bool), (-1, -np.inf)
    needed, it, n_models = np.iinfo(np.int64).max, 0, 0
    while it < min(needed, max_iter) or it < min_iter:
        it += 1
        idx = rng.choice(n_data, sample_size, replace=False)
        for model in fit(idx):
            n_models += 1
            e = np.asarray(errors(model), float)
            inl = np.isfinite(e) & (e < threshold)
            key = (int(inl.sum()), -float(e[inl].sum()))
            if key > best_key:
                best, best_inliers, best_key = model, inl, key
                needed = ransac_iterations(key[0] / n_data, sample_size, confidence)
    if best is None:
        raise ValueError(f"RANSAC found no model in {it} samples: every sample was degenerate")
    k = int(best_inliers.sum())
    p_chance = np.nan
    if chance is not None:
        p = chance(best) if callable(chance) else chance
        p = as_fraction(p, "chance (the probability that an unrelated item is an inlier)", closed=True)
        p_chance = chance_probability(k, n_data, sample_size, p, n_models)
    res = RansacResult(best, best_inliers, it, n_models=n_models, n_needed=int(min(needed, np.iinfo(np.int64).max)),
                       converged=bool(it >= needed), p_chance=p_chance)
    if p_chance > max_p_chance:
        raise ValueError(f"RANSAC's best model is no better than chance: {res.text()} (above {max_p_chance:g}; "
                         f"an unrelated item is an inlier with probability {p:.2g}). The data look random: "
                         "too many outliers, a threshold too large, or no relation to find")
    return res
