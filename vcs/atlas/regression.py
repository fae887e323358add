"""Shape -> flow regression (beyond the paper): ridge with leave-one-out cross-validated R^2.

Pure numpy; never imports plotting (:mod:`vcs.atlas.plots`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from vcs.errors import VCSInputError


def _safe_std(X: np.ndarray) -> np.ndarray:
    """Column standard deviations; columns that are constant (to round-off, e.g. the scores of a
    mode with no variance among the training samples) get inf, i.e. a standardised value of 0."""
    sx = X.std(0)
    return np.where(sx > 1e-9 * max(float(sx.max(initial=0.0)), 1e-300), sx, np.inf)


def _ridge_solve(X: np.ndarray, Y: np.ndarray, alpha: float) -> Callable[[ArrayLike], np.ndarray]:
    """Ridge with unpenalised intercept on standardised X. Returns a predict function."""
    mx, sx = X.mean(0), _safe_std(X)
    my = Y.mean(0)
    Z = (X - mx) / sx
    B = np.linalg.solve(Z.T @ Z + alpha * np.eye(Z.shape[1]), Z.T @ (Y - my))
    return lambda Xn: ((np.asarray(Xn) - mx) / sx) @ B + my


def _gcv_alpha(X: np.ndarray, Y: np.ndarray, alphas: np.ndarray | Sequence[float]) -> float:
    """alpha minimising the exact leave-one-out error of the ridge fit (hat-matrix shortcut)."""
    Z = (X - X.mean(0)) / _safe_std(X)
    Yc = Y - Y.mean(0)
    n = len(X)
    best, best_err = alphas[0], np.inf
    for a in alphas:
        H = Z @ np.linalg.solve(Z.T @ Z + a * np.eye(Z.shape[1]), Z.T) + 1.0 / n  # + intercept
        r = (Yc - (H - 1.0 / n) @ Yc) / np.maximum(1.0 - np.diag(H), 1e-12)[:, None]
        err = float(np.sum(r**2))
        if err < best_err:
            best, best_err = a, err
    return best


DEFAULT_ALPHAS = tuple(np.logspace(-6, 4, 21))

#: Fewest samples for which a leave-one-out R^2 is reported as meaningful (with k regressors, at
#: least k + 2 are needed as well: every fold must still fit k slopes and an intercept with one
#: residual degree of freedom).
MIN_LOO_SAMPLES = 5
#: R^2 at or above which a flow mode's prediction counts as ``good`` (below: ``weak``; <= 0: ``none``).
GOOD_SKILL_R2 = 0.5


def loo_sufficiency(n: int, k: int) -> tuple[str, str]:
    """Whether a leave-one-out R^2 over ``n`` samples with ``k`` regressors can say anything.

    Parameters
    ----------
    n : int
        Samples (included patients).
    k : int
        Regressors (shape scores).

    Returns
    -------
    status : {"ok", "insufficient_patients"}
    reason : str
        One line, e.g. ``"4 included patients: leave-one-out with k = 2 shape scores needs at least 5"``.
    """
    need = max(MIN_LOO_SAMPLES, k + 2)
    reason = f"{n} included patients: leave-one-out with k = {k} shape scores needs at least {need}"
    return ("ok" if n >= need else "insufficient_patients"), reason


def r2_skill(r2: float | None) -> str:
    """Verbal skill of a leave-one-out R^2.

    ``none`` for R^2 <= 0 (no better than predicting the cohort mean), ``weak`` for
    0 < R^2 < :data:`GOOD_SKILL_R2`, ``good`` above, ``undefined`` for nan/None (a flow mode without
    variance).
    """
    if r2 is None or not np.isfinite(r2):
        return "undefined"
    if r2 <= 0.0:
        return "none"
    return "weak" if r2 < GOOD_SKILL_R2 else "good"


def ridge_loo(X: ArrayLike, Y: ArrayLike, *, alphas: ArrayLike = DEFAULT_ALPHAS) -> dict[str, Any]:
    """Leave-one-out cross-validated ridge regression Y ~ X (beyond the paper).

    For each left-out sample, the regularisation alpha is chosen on the remaining samples by
    their own exact leave-one-out error (nested, so the reported R^2 is honest), the model
    (standardised X, unpenalised intercept) is fitted on them and predicts the left-out sample.

    Parameters
    ----------
    X : (n, k) or (n,) float
        Predictors, e.g. the first k shape scores (mm).
    Y : (n, m) or (n,) float
        Responses, e.g. flow scores.
    alphas : (a,) float
        Candidate regularisation strengths (on standardised X); a single value is used as is.

    Returns
    -------
    dict
        ``r2`` (m,) float = 1 - sum (y - y_loo)^2 / sum (y - mean y)^2 per column (can be
        negative; nan for a column without variance; a float for a 1-D ``Y``), ``predictions``
        (n, m) (or (n,)) leave-one-out predictions, ``alphas`` (n,) chosen per fold,
        ``alpha_full`` (float) chosen on all samples.

    Raises
    ------
    VCSInputError
        Fewer than 3 samples.
    """
    X = np.asarray(X, float)
    Y = np.asarray(Y, float)
    if X.ndim == 1:
        X = X[:, None]
    squeeze = Y.ndim == 1
    if squeeze:
        Y = Y[:, None]
    n = len(X)
    if n < 3:
        raise VCSInputError(f"leave-one-out regression needs at least 3 samples, got {n}")
    alphas = np.asarray(alphas, float)
    pred = np.empty_like(Y)
    chosen = np.empty(n)
    for i in range(n):
        keep = np.arange(n) != i
        a = _gcv_alpha(X[keep], Y[keep], alphas) if len(alphas) > 1 else alphas[0]
        chosen[i] = a
        pred[i] = _ridge_solve(X[keep], Y[keep], a)(X[i : i + 1])[0]
    ss = np.sum((Y - Y.mean(0)) ** 2, axis=0)
    # columns without variance (a PCA mode of round-off size) have no R^2: nan (null in atlas.json)
    r2 = 1.0 - np.sum((Y - pred) ** 2, axis=0) / np.where(ss > 1e-12 * max(float(ss.max()), 1e-300), ss, np.nan)
    return {
        "r2": r2[0] if squeeze else r2,
        "predictions": pred[:, 0] if squeeze else pred,
        "alphas": chosen,
        "alpha_full": float(_gcv_alpha(X, Y, alphas)),
    }
