"""Kernel partial least squares (Ouzounis, Kiliadis & Mousas), NIPALS on the Gram matrix.

Symbols of the paper and their names here:

==========================  =============================================
paper                       code
==========================  =============================================
X (source expressions)      ``X``, (n_pairs, n_features)
Y (target expressions)      ``Y``, (n_pairs, n_outputs)
Φ, K = Φ Φᵀ                 ``K`` (the Gram matrix of ``kernel``)
K_c (centred, eq. 8)        ``Kc`` = (I − 11ᵀ/n) K (I − 11ᵀ/n)
t, T (X scores)             ``t``, ``x_scores_`` (n_pairs, p)
u, U (Y scores)             ``u``, ``y_scores_`` (n_pairs, p)
c (Y weights)               ``c``
p (latent components)       ``n_components_``
K_test (eq. 10)             ``Kt``, centred as ``Ktc``
U (TᵀKU)⁻¹ TᵀY (eq. 10)     ``dual_coef_`` (n_pairs, n_outputs)
==========================  =============================================

The NIPALS loop (eqs. 3–7) alternates t = K u / ‖K u‖, c = Yᵀ t, u = Y c /
‖Y c‖ until t stops changing; the Gram matrix and Y are then deflated
(eq. 9). Prediction (eq. 10) is ``Ŷ = Ktc @ dual_coef_ + mean(Y)``, so a new
input costs one kernel row and one small matrix product, which is what the
runtime stage (:mod:`facepuppet.runtime.kpls.stage`) evaluates.

With the linear kernel the scores span the same space as ordinary PLS
(NIPALS with X deflation), so predictions equal those of scikit-learn's
``PLSRegression(scale=False)``.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg import solve_triangular

from facepuppet.runtime.errors import UsageError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

KERNELS = ("rbf", "poly", "linear")
AUTO_KERNELS = ("linear", "rbf", "poly")  # tried by kernel="auto", in this order (ties go to the first)


def check_pairs(X: ArrayLike, Y: ArrayLike, who: str = "KernelPLS.fit") -> tuple[np.ndarray, np.ndarray]:
    """Training pairs as float64 2-D arrays, or ValueError saying what is wrong.

    Parameters
    ----------
    X : array-like of shape (n_pairs, n_features), source side
    Y : array-like of shape (n_pairs,) or (n_pairs, n_outputs), target side
    """
    X = check_inputs(X, f"{who}: X")
    Y = np.asarray(Y, dtype=np.float64)
    if Y.ndim == 1:
        Y = Y[:, None]
    if Y.ndim != 2:
        raise ValueError(f"{who}: Y must have shape (n_pairs, n_outputs), got {Y.shape}")
    if len(X) != len(Y):
        raise ValueError(f"{who}: unequal numbers of pairs: X has {len(X)} rows, Y has {len(Y)}")
    if not np.isfinite(Y).all():
        raise ValueError(f"{who}: Y contains NaN or infinity at {int((~np.isfinite(Y)).sum())} entries")
    if len(X) < 2:
        raise ValueError(f"{who}: needs at least 2 pairs to fit, got a single pair" if len(X) == 1
                         else f"{who}: needs at least 2 pairs to fit, got none")
    return X, Y


def check_inputs(X: ArrayLike, what: str) -> np.ndarray:
    """Inputs as a finite float64 array of shape (n, n_features), or ValueError."""
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] == 0:
        raise ValueError(f"{what} must have shape (n, n_features) with n_features >= 1, got {X.shape}")
    if not np.isfinite(X).all():
        raise ValueError(f"{what} contains NaN or infinity at {int((~np.isfinite(X)).sum())} entries")
    return X


def kernel_matrix(A: np.ndarray, B: np.ndarray, kernel: str, gamma: float, coef0: float,
                  degree: int) -> np.ndarray:
    """Gram matrix k(a_i, b_j) of shape (len(A), len(B)), float64.

    rbf: exp(−γ‖a − b‖²); poly: (γ aᵀb + coef0)^degree; linear: aᵀb.
    """
    if kernel == "linear":
        return A @ B.T
    if kernel == "poly":
        return (gamma * (A @ B.T) + coef0) ** degree
    sq = (A * A).sum(1)[:, None] + (B * B).sum(1)[None, :] - 2.0 * (A @ B.T)
    return np.exp(-gamma * np.maximum(sq, 0.0))


def centre_gram(K: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Centred Gram matrix and its centring terms (column means, grand mean)."""
    col_mean = K.mean(axis=0)
    grand = float(col_mean.mean())
    # Ouzounis eq. 8: K_c = (I − 11ᵀ/n) K (I − 11ᵀ/n)
    Kc = K - col_mean[None, :] - K.mean(axis=1)[:, None] + grand
    return Kc, col_mean, grand


def nipals(Kc: np.ndarray, Yc: np.ndarray, n_components: int, tol: float = 1e-6,
           max_iter: int = 2000, solver: str = "eigh",
           exhausted: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
    """Scores T, U of shape (n, p) by kernel NIPALS with Gram deflation, p <= n_components.

    The inner loop of eqs. 3–7 is a power iteration: one pass maps c to
    (Yᵀ K Y) c up to scale, so its fixed point is the dominant eigenvector of
    the small symmetric matrix Yᵀ K Y (m × m). ``solver="eigh"`` takes that
    fixed point directly (exact, and immune to the slow convergence of the
    iteration when the two largest eigenvalues nearly tie); ``solver="power"``
    iterates eqs. 3–7 as written and warns when it stops before ``tol``.
    Components stop early (fewer than ``n_components`` columns come back) once
    the deflated Yᵀ K Y holds less than ``exhausted`` of its first value:
    what is left is rounding noise, whose directions are arbitrary.

    Parameters
    ----------
    Kc : ndarray of shape (n, n), centred Gram matrix
    Yc : ndarray of shape (n, m), centred outputs
    """
    if solver not in ("eigh", "power"):
        raise ValueError(f"nipals: solver must be 'eigh' or 'power', got {solver!r}")
    n = len(Kc)
    K, Y = Kc.copy(), Yc.copy()
    T = np.zeros((n, n_components))
    U = np.zeros((n, n_components))
    KY = K @ Y
    first = None
    for a in range(n_components):
        small = Y.T @ KY  # Yᵀ K Y, (m, m): eqs. 3–7 iterate c ← Yᵀ K Y c up to scale
        small = 0.5 * (small + small.T)
        if solver == "eigh":
            vals, vecs = np.linalg.eigh(small)
            top, c = float(vals[-1]), vecs[:, -1]
        else:
            c, top = _power_iteration(small, Y, tol, max_iter, a)
        first = top if first is None else first
        if not first > 0 or top <= exhausted * first:
            return T[:, :a], U[:, :a]
        t = KY @ c  # Ouzounis eq. 3: t = Φ Φᵀ u = K u, u = Y c
        norm = np.linalg.norm(t)
        if norm == 0.0:
            return T[:, :a], U[:, :a]
        t /= norm  # Ouzounis eq. 4: t ← t / ‖t‖
        c = Y.T @ t  # Ouzounis eq. 5: c = Yᵀ t
        u = Y @ c  # Ouzounis eq. 6: u = Y c
        u /= max(np.linalg.norm(u), 1e-300)  # Ouzounis eq. 7: u ← u / ‖u‖
        T[:, a], U[:, a] = t, u
        Kt = K @ t
        tY = t @ Y
        # Ouzounis eq. 9: K ← (I − t tᵀ) K (I − t tᵀ), expanded (in place, O(n²))
        K -= np.outer(t, Kt)
        K -= np.outer(Kt, t)
        K += (t @ Kt) * np.outer(t, t)
        Y -= np.outer(t, tY)  # Ouzounis eq. 9: Y ← Y − t tᵀ Y
        # K Y after both deflations, O(n m): (I − t tᵀ)(K Y − K t tᵀY)
        KY -= np.outer(Kt, tY)
        KY -= np.outer(t, t @ KY)
    return T, U


def _power_iteration(small: np.ndarray, Y: np.ndarray, tol: float, max_iter: int,
                     a: int) -> tuple[np.ndarray, float]:
    """Eqs. 3–7 iterated: dominant eigenvector c of ``small`` = Yᵀ K Y and its Rayleigh quotient."""
    c = Y[int(np.argmax(np.abs(Y).sum(1)))].copy()  # u = Y c starts on the largest output row
    if not np.any(c):
        c = np.ones(Y.shape[1])
    c /= np.linalg.norm(c)
    for _ in range(max_iter):
        # Ouzounis eqs. 3–7 folded: t = K u / ‖K u‖ with u = Y c (eqs. 3, 4, 6), then c = Yᵀ t (eq. 5);
        # only the direction of c matters, so one step is c ← (Yᵀ K Y) c / ‖·‖
        c_new = small @ c
        norm = np.linalg.norm(c_new)
        if norm == 0.0:
            return c, 0.0
        c_new /= norm
        done = np.linalg.norm(c_new - c) < tol
        c = c_new
        if done:
            break
    else:
        warnings.warn(f"KernelPLS: NIPALS did not converge in {max_iter} iterations for "
                      f"component {a + 1}", RuntimeWarning, stacklevel=4)
    return c, float(c @ small @ c)


def dual_coefficients(Kc: np.ndarray, Yc: np.ndarray, T: np.ndarray, U: np.ndarray) -> np.ndarray:
    """U (Tᵀ K U)⁻¹ Tᵀ Y of shape (n, m): the dual coefficients of eq. 10."""
    # Ouzounis eq. 10: Ŷ = K_t U (Tᵀ K U)⁻¹ Tᵀ Y
    return U @ np.linalg.solve(T.T @ Kc @ U, T.T @ Yc)


class KernelPLS:
    """Kernel PLS regression (Ouzounis, Kiliadis & Mousas), scikit-learn style.

    Parameters
    ----------
    n_components : int or "auto"; "auto" picks the count with the lowest
        cross-validated squared error among 1..max_components
    kernel : "rbf", "poly", "linear" or "auto"; "auto" cross-validates each of
        :data:`AUTO_KERNELS` (rbf at every width of ``gamma_scales``) and keeps the
        lowest error; needs ``n_components="auto"`` or a count every kernel reaches
    gamma : float or None; None gives 1 / median squared distance between
        training inputs (rbf) or 1 / n_features (poly)
    degree : int, poly kernel degree
    coef0 : float, poly kernel offset
    max_components : int or None, upper bound searched by "auto"; None: every
        count the cross-validation folds allow (n_pairs − fold size − 1), less
        once the deflated Gram matrix is exhausted
    cv_folds : int, folds for "auto"
    tol, max_iter : convergence settings of ``solver="power"``
    solver : "eigh" (the NIPALS fixed point of eqs. 3–7 taken directly) or
        "power" (eqs. 3–7 iterated), see :func:`nipals`
    random_state : int, seed of the cross-validation split
    gamma_scales : tuple of float; with "auto" components, an rbf kernel and no
        given gamma, the widths 1 / median squared distance times each scale
        are cross-validated too

    Attributes
    ----------
    n_components_ : int, latent components used
    X_fit_ : ndarray of shape (n_pairs, n_features), float64, training inputs
    gamma_ : float, the kernel scale used
    dual_coef_ : ndarray of shape (n_pairs, n_outputs), eq. 10's U (TᵀKU)⁻¹ TᵀY
    x_scores_, y_scores_ : ndarray of shape (n_pairs, n_components_)
    kernel_col_mean_ : ndarray of shape (n_pairs,), centring term of test kernels
    kernel_grand_mean_ : float, centring term
    y_mean_ : ndarray of shape (n_outputs,)
    kernel_ : str, the kernel used ("auto" resolved)
    cv_errors_ : dict of int to float, mean squared CV error per count at the chosen kernel and gamma
        (auto only); counts some fold cannot reach (its Gram matrix exhausted) are left out, never inf
    cv_scores_ : dict of str to float, lowest CV error of each kernel (and rbf width) tried (auto only)
    """

    def __init__(self, n_components: int | str = "auto", kernel: str = "rbf", gamma: float | None = None,
                 degree: int = 2, coef0: float = 1.0, max_components: int | None = None,
                 cv_folds: int = 5, tol: float = 1e-6, max_iter: int = 2000, random_state: int = 0,
                 gamma_scales: tuple = (1.0, 0.1, 0.01, 0.001), solver: str = "eigh") -> None:
        self.n_components = n_components
        self.kernel = kernel
        self.gamma = gamma
        self.degree = degree
        self.coef0 = coef0
        self.max_components = max_components
        self.cv_folds = cv_folds
        self.tol = tol
        self.max_iter = max_iter
        self.random_state = random_state
        self.gamma_scales = gamma_scales
        self.solver = solver

    # -- fitting -----------------------------------------------------------
    def _check_settings(self, n: int) -> None:
        if self.kernel not in (*KERNELS, "auto"):
            raise ValueError(f"KernelPLS: kernel must be one of {(*KERNELS, 'auto')}, got {self.kernel!r}")
        nc = self.n_components
        if nc != "auto":
            if not isinstance(nc, (int, np.integer)) or isinstance(nc, bool) or nc < 1:
                raise ValueError(f"KernelPLS: n_components must be 'auto' or an int >= 1, got {nc!r}")
            if nc > n - 1:
                raise UsageError(f"KernelPLS: too many components: n_components={nc} but {n} pairs allow "
                                 f"at most {n - 1} (centring removes one dimension)")

    def _gram(self, A, B):
        return kernel_matrix(A, B, self.kernel_, self.gamma_, self.coef0, self.degree)

    def _scale(self, X: np.ndarray, kernel: str) -> float:
        if self.gamma is not None:
            return float(self.gamma)
        if kernel == "rbf":
            sq = kernel_matrix(X, X, "linear", 0, 0, 1)
            d = np.diag(sq)
            dist = d[:, None] + d[None, :] - 2 * sq
            med = float(np.median(dist[np.triu_indices(len(X), 1)]))
            return 1.0 / med if med > 0 else 1.0
        return 1.0 / X.shape[1]

    def candidates(self) -> list[tuple[str, float]]:
        """(kernel, gamma scale) pairs the fit cross-validates (one, with nothing to choose)."""
        kernels = AUTO_KERNELS if self.kernel == "auto" else (self.kernel,)
        out = []
        for kernel in kernels:
            widths = self.gamma_scales if (kernel == "rbf" and self.gamma is None
                                           and self.n_components == "auto") else (1.0,)
            out += [(kernel, float(scale)) for scale in widths]
        return out if (len(out) > 1 or self.n_components == "auto") else []

    def fit(self, X: ArrayLike, Y: ArrayLike, progress: Callable[[str], None] | None = None) -> KernelPLS:
        """Fit on paired rows of X (n_pairs, n_features) and Y (n_pairs, n_outputs); returns self.

        ``progress`` is called with a short note after each cross-validation fold (``cv_folds``
        calls per entry of :meth:`candidates`), so a long fit can show how far it is.
        """
        X, Y = check_pairs(X, Y)
        self._check_settings(len(X))
        self.X_fit_ = X
        self.y_mean_ = Y.mean(axis=0)
        candidates = self.candidates()
        if candidates:
            # kernel, width and components by cross-validation; a fixed count is scored at that count
            best = None
            self.cv_scores_ = {}
            for kernel, scale in candidates:
                self.kernel_, self.gamma_ = kernel, self._scale(X, kernel) * scale
                label = kernel if kernel != "rbf" or len(self.gamma_scales) == 1 or self.gamma is not None \
                    else f"rbf x{scale:g}"
                errors = self._cross_validate(self._gram(X, X), Y, progress, label)
                if self.n_components == "auto":
                    p = min(errors, key=errors.get)
                else:
                    p = int(self.n_components)
                    if p not in errors:
                        continue
                self.cv_scores_[label] = errors[p]
                if best is None or errors[p] < best[0]:
                    best = (errors[p], kernel, self.gamma_, p, errors)
            if best is None:
                raise UsageError(f"KernelPLS: no kernel of {AUTO_KERNELS} reaches {self.n_components} "
                                 f"components on every cross-validation fold (use fewer components)")
            _, self.kernel_, self.gamma_, p, self.cv_errors_ = best
        else:
            self.kernel_ = self.kernel
            self.gamma_ = self._scale(X, self.kernel)
            p = int(self.n_components)
        K = self._gram(X, X)
        Kc, self.kernel_col_mean_, self.kernel_grand_mean_ = centre_gram(K)
        Yc = Y - self.y_mean_
        T, U = nipals(Kc, Yc, p, self.tol, self.max_iter, self.solver)
        if T.shape[1] < p:
            raise UsageError(f"KernelPLS: too many components: the Gram matrix is exhausted after "
                             f"{T.shape[1]} of the {p} components asked for (use fewer components)")
        self.x_scores_, self.y_scores_ = T, U
        self.dual_coef_ = dual_coefficients(Kc, Yc, self.x_scores_, self.y_scores_)
        self.n_components_ = p
        return self

    def _cross_validate(self, K: np.ndarray, Y: np.ndarray, progress: Callable[[str], None] | None = None,
                        label: str = "") -> dict[int, float]:
        """Mean squared error per component count over ``cv_folds`` folds (one NIPALS per fold).

        Only counts every fold reaches are scored: a fold whose Gram matrix is exhausted after q
        components (its training pairs span fewer dimensions) cannot support more, so the search
        stops at the smallest such q. Every score returned is finite.
        """
        n = len(K)
        folds = np.array_split(np.random.default_rng(self.random_state).permutation(n),
                               min(self.cv_folds, n))
        p_max = n - len(folds[0]) - 1
        if self.max_components is not None:
            p_max = min(int(self.max_components), p_max)
        p_max = max(1, p_max)
        sse = np.zeros(p_max)
        reached = p_max
        for number, test in enumerate(folds, 1):
            train = np.setdiff1d(np.arange(n), test)
            Kc, col_mean, grand = centre_gram(K[np.ix_(train, train)])
            y_mean = Y[train].mean(0)
            Yc = Y[train] - y_mean
            Kt = K[np.ix_(test, train)]
            Ktc = Kt - col_mean[None, :] - Kt.mean(1)[:, None] + grand
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                T, U = nipals(Kc, Yc, reached, self.tol, self.max_iter, self.solver)
            q = T.shape[1]
            # Tᵀ K U is upper triangular (Gram deflation, eq. 9), so the leading p × p block of its
            # inverse is the inverse of its leading block, and eq. 10 with the first p components is
            # a running sum: Ŷ_p = Σ_{j<p} (K_tc U R⁻¹)_{:, j} (Tᵀ Y)_j
            R = np.triu(T.T @ Kc @ U)
            diag = np.abs(np.diag(R))
            # a count whose leading block is singular is unsupported too
            ok = diag > 1e-12 * max(float(diag.max(initial=0.0)), 1e-300)
            q = int(np.argmin(ok)) if not ok.all() else q
            reached = min(reached, q)
            if reached == 0:
                break
            Rinv = solve_triangular(R[:q, :q], np.eye(q))
            A, TY = Ktc @ U[:, :q] @ Rinv, T[:, :q].T @ Yc
            pred = np.broadcast_to(y_mean, Y[test].shape).copy()
            for p in range(reached):
                pred += np.outer(A[:, p], TY[p])  # Ouzounis eq. 10 with the first p + 1 components
                sse[p] += ((pred - Y[test]) ** 2).sum()
            if progress is not None:
                progress(f"{label} fold {number}/{len(folds)}")
        if reached == 0:
            raise UsageError("KernelPLS: cross-validation found no component: a fold's training pairs do "
                             "not vary (give more, or more varied, pairs)")
        return {p: float(sse[p - 1] / Y.size) for p in range(1, reached + 1)}

    # -- prediction --------------------------------------------------------
    def centred_kernel(self, X: np.ndarray) -> np.ndarray:
        """Test kernel rows centred like the training Gram matrix, (n, n_pairs) float64."""
        Kt = self._gram(X, self.X_fit_)
        # Ouzounis eq. 8 for test rows: K_tc = (K_t − 1 1ᵀK/n)(I − 11ᵀ/n)
        return Kt - self.kernel_col_mean_[None, :] - Kt.mean(axis=1)[:, None] + self.kernel_grand_mean_

    def predict(self, X: ArrayLike) -> np.ndarray:
        """Outputs of shape (n, n_outputs), float64, for inputs X (n, n_features)."""
        if not hasattr(self, "dual_coef_"):
            raise ValueError("KernelPLS.predict: this model is not fitted yet; call fit(X, Y) first")
        X = check_inputs(X, "KernelPLS.predict: X")
        if X.shape[1] != self.X_fit_.shape[1]:
            raise ValueError(f"KernelPLS.predict: X has {X.shape[1]} features, the model was fitted "
                             f"on {self.X_fit_.shape[1]}")
        # Ouzounis eq. 10: Ŷ = K_tc U (Tᵀ K U)⁻¹ Tᵀ Y (+ the mean removed before fitting)
        return self.centred_kernel(X) @ self.dual_coef_ + self.y_mean_

    def export_arrays(self) -> dict:
        """What the runtime needs to predict: inputs, dual coefficients, centring terms, kernel."""
        if not hasattr(self, "dual_coef_"):
            raise ValueError("KernelPLS.export_arrays: this model is not fitted yet")
        return {
            "train_inputs": self.X_fit_, "dual_coef": self.dual_coef_,
            "kernel_col_mean": self.kernel_col_mean_, "kernel_grand_mean": self.kernel_grand_mean_,
            "target_mean": self.y_mean_, "kernel": self.kernel_, "gamma": self.gamma_,
            "coef0": float(self.coef0), "degree": int(self.degree),
        }
