"""Robust losses for bundle adjustment, with scipy's conventions: ``ρ(z)`` with ``z = (r / f_scale)²``, applied
to each residual component, and the objective ``0.5 Σ f_scale² ρ(r² / f_scale²)``.

Robust least squares is minimised in two phases (see :func:`labutils.bundle.bundle_adjust`): iteratively
reweighted least squares (weights ``ρ'``) while far from the optimum, then the exact second-order curvature
``ρ' + 2zρ''`` (floored at ``CURVATURE_FLOOR ρ'``) once the relative cost decrease is below ``SECOND_ORDER_AFTER``.
"""
import numpy as np

LOSSES = ("linear", "huber", "soft_l1", "cauchy", "arctan")
SECOND_ORDER_AFTER = 1e-3      # relative cost decrease below which LM leaves plain IRLS
CURVATURE_FLOOR = 0.01         # ... and the floor of the second-order curvature, times rho'


def rho(z, loss):
    """``ρ(z)``, ``ρ'(z)`` and ``ρ''(z)`` for ``z = (r / f_scale)²`` (scipy's definitions).

    >>> [float(v[0]) for v in rho(np.array([4.0]), "huber")]
    [3.0, 0.5, -0.0625]
    """
    if loss == "linear":
        return z, np.ones_like(z), np.zeros_like(z)
    if loss == "huber":
        big = z > 1
        sz = np.sqrt(np.where(big, z, 1.0))
        return np.where(big, 2 * sz - 1, z), np.where(big, 1 / sz, 1.0), np.where(big, -0.5 / sz ** 3, 0.0)
    if loss == "soft_l1":
        s = np.sqrt(1 + z)
        return 2 * (s - 1), 1 / s, -0.5 / s ** 3
    if loss == "cauchy":
        return np.log1p(z), 1 / (1 + z), -1 / (1 + z) ** 2
    if loss == "arctan":
        return np.arctan(z), 1 / (1 + z ** 2), -2 * z / (1 + z ** 2) ** 2
    raise ValueError(f"loss must be one of {LOSSES}; got {loss!r}")


def robust_cost(r, loss="linear", f_scale=1.0):
    """The objective ``0.5 Σ f_scale² ρ(r² / f_scale²)`` over all residual components (px²).

    >>> robust_cost(np.array([3.0, 4.0]))
    12.5
    >>> robust_cost(np.array([3.0, 0.5]), "huber", 1.0)   # 0.5 (2·3 - 1) + 0.5 · 0.25
    2.625
    """
    r = np.asarray(r, float).ravel()
    return float(0.5 * f_scale ** 2 * rho((r / f_scale) ** 2, loss)[0].sum())


def scipy_loss(loss, second_order):
    """``loss`` as a callable for ``least_squares``, with the curvature model LM-Schur uses.

    ``least_squares`` scales each residual's Jacobian row by ``sqrt(ρ' + 2zρ'')`` (clamped at machine
    epsilon). With ``second_order=False`` we report ``ρ'' = 0``: IRLS, whose curvature ``ρ'`` stays positive
    whatever the residual. scipy's own choice, the exact curvature from the start, stalls from a far start
    where most residuals are beyond the scale (on the dinosaur with a Cauchy loss it ended 80 times above
    LM-Schur's cost after 300 iterations). With ``second_order=True``: the exact curvature floored at
    ``0.01 ρ'``, as in LM-Schur's second phase.
    """
    def loss_fn(z):
        out = np.stack(rho(z, loss))
        if second_order:
            floor = CURVATURE_FLOOR * out[1]
            low = out[1] + 2 * z * out[2] < floor
            out[2] = np.where(low, (floor - out[1]) / (2 * np.maximum(z, 1e-300)), out[2])
        else:
            out[2] = 0.0
        return out

    loss_fn.__name__ = f"{loss}_{'second_order' if second_order else 'irls'}"
    return loss_fn

