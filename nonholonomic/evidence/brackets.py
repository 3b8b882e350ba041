"""Machine-checked Poisson structures: antisymmetry, the Jacobi identity, Casimirs and the rank.

A structure is its Poisson matrix ``P_ij = {x_i, x_j}``
(:class:`nonholonomic.hamiltonization.poisson.PoissonStructure`). For a skew matrix the Jacobi identity
``{x_i, {x_j, x_k}} + cycl. = 0`` is the vanishing of the Jacobiator

    J_ijk = Σ_l (P_il ∂_l P_jk + P_jl ∂_l P_ki + P_kl ∂_l P_ij),        i < j < k,

and a function C is a Casimir iff ``{C, x_i} = Σ_j ∂_j C P_ji ≡ 0`` for every i.

Symbolic checks keep the parameters as symbols: an expression is put over a common denominator
(``together``) and its numerator expanded, which decides rational functions exactly (the e(3) bracket,
Chaplygin's ball bracket eq. (2604-6) and its Casimir γ² are rational; the Casimir (L, γ)/ρ_μ contains
``sqrt(det I_Q)`` and still reduces this way). A non-rational numerator that does not expand to 0 is
evaluated at random rational points with 50 digits: a clearly non-zero value disproves the identity,
otherwise the check stays undecided. Each proof runs to its end and is cached per process
(:mod:`nonholonomic.bounded`); an expression (a Jacobiator, a bracket {C, x_i}, an entry P_ij + P_ji) of
more than ``max_proof_ops`` sympy operations (:mod:`nonholonomic.work_limits`) is not tried, and the check
says so: the same verdict and words on every machine, whatever its load.

Pointwise checks evaluate the individual terms (exact symbolic derivatives, compiled with
:func:`nonholonomic.numerics.kernels.vectorize` over ``variables + parameters``) and report
``|Σ terms| / Σ |terms|``, the residual relative to the size of what cancels, maximised over points.

Checked in tests/unit/test_brackets.py: eq. (2604-6) as printed satisfies Jacobi for symbolic I, D
(ERRATA, "verified as printed"), with Casimirs γ² and (L, γ)/ρ_μ. Jacobi alone does not fix the
coefficient of its D-term: with D → 2D in that term (ρ_μ unchanged) the bracket is still Poisson,
but (L, γ)/ρ_μ is no longer a Casimir; with J_i J_j → I_i I_j Jacobi fails.
"""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from functools import lru_cache
from typing import Any

import numpy as np
import sympy as sp
from sympy.core.function import AppliedUndef

from nonholonomic import bounded, work_limits
from nonholonomic.evidence.measure import CheckEvidence
from nonholonomic.hamiltonization.poisson import PoissonStructure
from nonholonomic.numerics.kernels import vectorize
from nonholonomic.work_limits import MAX_PROOF_OPS, WorkLimits, operations, over

#: Pointwise relative residual accepted as round-off.
POINTWISE_TOLERANCE = 1e-10
#: A pointwise relative residual above this is a disproof, not round-off (used when the symbolic
#: check is undecided).
POINTWISE_DISPROOF = 1e-6
#: Singular values below ``RANK_RTOL · σ_max`` count as zero in :func:`rank_at`.
RANK_RTOL = 1e-9
#: Digits and threshold of the numeric confirmation that a non-rational expression is non-zero.
_CONFIRM_DIGITS = 50
_CONFIRM_THRESHOLD = 1e-12
_CONFIRM_POINTS = 6
#: Largest user bracket accepted (the Jacobiators grow like n³ and each has 3n terms).
MAX_USER_DIMENSION = 16


# --------------------------------------------------------------------------------------------
# Deciding ``expr ≡ 0``
# --------------------------------------------------------------------------------------------

def _random_value(symbol: sp.Symbol, rng: np.random.Generator, scale: float) -> sp.Rational:
    """A random rational respecting the symbol's sign assumptions."""
    if symbol.is_positive:
        v = rng.uniform(0.5, 3.0)
    elif symbol.is_nonnegative:
        v = rng.uniform(0.1, 2.0)
    elif symbol.is_negative:
        v = -rng.uniform(0.5, 3.0)
    else:
        v = scale * rng.uniform(-1.0, 1.0)
    return sp.Rational(round(v * 1000), 1000) or sp.Rational(1, 1000)


def _confirm_nonzero(expr: sp.Expr, seed: int = 0) -> tuple[bool | None, str]:
    """Evaluate ``expr`` at random rational points with 50 digits: False (≢ 0) if clearly non-zero there."""
    rng = np.random.default_rng(seed)
    symbols = sorted(expr.free_symbols, key=str)
    tried = 0
    for attempt in range(4 * _CONFIRM_POINTS):
        point = {s: _random_value(s, rng, 2.0 / (1 + attempt // _CONFIRM_POINTS)) for s in symbols}
        try:
            value = sp.N(expr.xreplace(point), _CONFIRM_DIGITS)
            value = complex(value)
        except (TypeError, ValueError, ZeroDivisionError):
            continue
        if not np.isfinite(value) or abs(value.imag) > 0:
            continue  # off the real domain (e.g. a negative radicand): try another point
        tried += 1
        if abs(value.real) > _CONFIRM_THRESHOLD:
            where = ", ".join(f"{s}={point[s]}" for s in symbols)
            return False, f"= {value.real:.6g} at {where} ({_CONFIRM_DIGITS}-digit evaluation)"
        if tried >= _CONFIRM_POINTS:
            break
    if tried == 0:
        return None, "not reduced to 0 and no real random point to evaluate it at"
    return None, (f"not reduced to 0 symbolically, numerically zero (< {_CONFIRM_THRESHOLD:g}) at {tried} random "
                  f"rational points")


def _is_rational_polynomial(expr: sp.Expr) -> bool:
    """Whether ``expr`` is a polynomial in its free symbols with rational coefficients."""
    if expr.is_Rational:
        return True
    symbols = sorted(expr.free_symbols, key=str)
    if not symbols or not expr.is_polynomial(*symbols):
        return False
    return sp.Poly(expr, *symbols).domain in (sp.ZZ, sp.QQ)


def _vanishes(expr: sp.Expr, max_ops: int = MAX_PROOF_OPS) -> tuple[bool | None, str]:
    """Whether ``expr ≡ 0``: numerator over a common denominator, expanded; else numeric confirmation.
    Not tried (None, the reason) on an expression of more than ``max_ops`` sympy operations."""
    expr = sp.sympify(expr)
    if expr == 0:
        return True, "is 0"
    skipped = over(operations(expr), max_ops, "max_proof_ops")
    if skipped is not None:
        return None, skipped
    numerator = sp.expand(sp.numer(sp.together(expr)))
    if numerator == 0:
        return True, "numerator over a common denominator expands to 0"
    terms = len(sp.Add.make_args(numerator))
    if _is_rational_polynomial(numerator):
        # An expanded non-zero polynomial with rational coefficients is not the zero function.
        return False, f"numerator over a common denominator is a non-zero polynomial with {terms} terms"
    verdict, detail = _confirm_nonzero(expr)
    return verdict, f"numerator ({terms} terms) {detail}"


def _key(ps: PoissonStructure) -> tuple:
    return (ps.variables, tuple(ps.matrix))


# --------------------------------------------------------------------------------------------
# Jacobi identity
# --------------------------------------------------------------------------------------------

def _triples(n: int) -> list[tuple[int, int, int]]:
    return list(itertools.combinations(range(n), 3))


def jacobiator_terms(ps: PoissonStructure, i: int, j: int, k: int) -> list[sp.Expr]:
    """The non-zero summands ``P_il ∂_l P_jk, P_jl ∂_l P_ki, P_kl ∂_l P_ij`` of ``J_ijk`` (l = 1..n)."""
    P, x = ps.matrix, ps.variables
    terms = []
    for l, xl in enumerate(x):
        for a, b, c in ((i, j, k), (j, k, i), (k, i, j)):
            term = P[a, l] * sp.diff(P[b, c], xl)
            if term != 0:
                terms.append(term)
    return terms


def _prove_jacobi(ps: PoissonStructure, max_ops: int = MAX_PROOF_OPS) -> tuple[bool | None, str]:
    names = [str(v) for v in ps.variables]
    undecided = []
    for i, j, k in _triples(len(ps.variables)):
        verdict, detail = _vanishes(sp.Add(*jacobiator_terms(ps, i, j, k)), max_ops)
        if verdict is False:
            return False, f"J for ({names[i]}, {names[j]}, {names[k]}): {detail}"
        if verdict is None:
            undecided.append(f"({names[i]}, {names[j]}, {names[k]}): {detail}")
    if undecided:
        return None, "undecided Jacobiators " + "; ".join(undecided)
    return True, f"all {len(_triples(len(ps.variables)))} Jacobiators J_ijk (i<j<k) reduce to 0, parameters symbolic"


def _jacobi_task(ps: PoissonStructure, limits: WorkLimits) -> tuple[tuple, Callable[..., Any], tuple]:
    return ("jacobi", limits.max_proof_ops) + _key(ps), _prove_jacobi, (ps, limits.max_proof_ops)


def jacobi_symbolic(ps: PoissonStructure, limits: WorkLimits = work_limits.DEFAULT) -> tuple[bool | None, str]:
    """Whether every Jacobiator ``J_ijk`` (i < j < k) vanishes identically, parameters symbolic.

    Parameters
    ----------
    ps : the structure (its matrix ``P_ij = {x_i, x_j}``).
    limits : each Jacobiator is tried when it has at most ``limits.max_proof_ops`` sympy operations
        (else it is undecided, the detail names the limit). The proof runs to its end in a thread of
        its own and is cached per structure and limit (:mod:`nonholonomic.bounded`).

    Returns
    -------
    (verdict, detail)
        ``True`` (proved), ``False`` (a Jacobiator is not identically zero; the detail names it) or
        ``None`` (undecided: a Jacobiator past the limit, or a non-rational expression not reduced).

    Raises
    ------
    nonholonomic.bounded.SafetyCapExceeded
        If the proof outlives the service's safety cap (a failure, not a verdict).
    """
    return bounded.prove(*_jacobi_task(ps, limits))


class _GroupedSums:
    """Compiled terms grouped into sums: ``max over points and groups of |Σ terms| / Σ |terms|``."""

    def __init__(self, groups: Sequence[Sequence[sp.Expr]], args: Sequence[sp.Symbol]) -> None:
        flat = [t for g in groups for t in g]
        self.kernel = vectorize(flat or [sp.Integer(0)], args)
        self.groups = np.zeros((max(len(flat), 1), max(len(groups), 1)))
        row = 0
        for col, g in enumerate(groups):
            self.groups[row:row + len(g), col] = 1.0
            row += len(g)

    def residuals(self, points: np.ndarray, parameters: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per point the largest relative residual over the groups, and a mask of finite points."""
        with np.errstate(all="ignore"):  # poles and negative radicands give inf/NaN rows, skipped below
            terms = self.kernel(points, parameters)
        finite = np.all(np.isfinite(terms), axis=1)
        terms = np.where(finite[:, None], terms, 0.0)
        total = np.abs(terms @ self.groups)
        scale = np.abs(terms) @ self.groups
        rel = np.where(scale > 0, total / np.where(scale > 0, scale, 1.0), 0.0)
        return np.max(rel, axis=1), finite


@lru_cache(maxsize=64)
def _jacobi_kernel(ps: PoissonStructure) -> _GroupedSums:
    groups = [jacobiator_terms(ps, *t) for t in _triples(len(ps.variables))]
    return _GroupedSums(groups, ps.variables + ps.parameters)


@lru_cache(maxsize=64)
def _matrix_kernel(ps: PoissonStructure) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    return vectorize(list(ps.matrix), ps.variables + ps.parameters)


def _parameter_vector(ps: PoissonStructure, parameters: np.ndarray | None) -> np.ndarray:
    p = np.zeros(0) if parameters is None else np.asarray(parameters, dtype=float).ravel()
    if p.size != len(ps.parameters):
        raise ValueError(f"{ps.name} needs {len(ps.parameters)} parameters "
                         f"({', '.join(map(str, ps.parameters)) or 'none'}), got {p.size}")
    return p


def _points(ps: PoissonStructure, points: np.ndarray) -> np.ndarray:
    X = np.atleast_2d(np.asarray(points, dtype=float))
    if X.shape[1] != len(ps.variables):
        raise ValueError(f"points must have {len(ps.variables)} columns ({', '.join(map(str, ps.variables))}), "
                         f"got shape {X.shape}")
    return X


def _max_residual(kernel: _GroupedSums, X: np.ndarray, p: np.ndarray) -> float:
    rel, finite = kernel.residuals(X, p)
    return float(np.max(rel[finite])) if np.any(finite) else float("nan")


def jacobi_pointwise(ps: PoissonStructure, points: np.ndarray, parameters: np.ndarray | None = None) -> float:
    """``max over points and i<j<k of |J_ijk| / Σ |terms of J_ijk|``.

    The terms are ``P_il ∂_l P_jk`` etc. with exact (symbolic) derivatives, compiled once per
    structure. A Jacobiator all of whose terms vanish at a point counts as 0; points where a term is
    not finite (a pole of the bracket) are skipped; NaN if no point is left.

    Parameters
    ----------
    points : shape ``(m, n)``, columns in the order of ``ps.variables``.
    parameters : values of ``ps.parameters`` in order (required iff the structure has parameters).
    """
    return _max_residual(_jacobi_kernel(ps), _points(ps, points), _parameter_vector(ps, parameters))


# --------------------------------------------------------------------------------------------
# Casimirs
# --------------------------------------------------------------------------------------------

def casimir_brackets(ps: PoissonStructure, C: sp.Expr) -> list[list[sp.Expr]]:
    """For each i, the non-zero summands ``∂_j C · P_ji`` of ``{C, x_i}``."""
    grad = [sp.diff(C, x) for x in ps.variables]
    n = len(ps.variables)
    return [[t for t in (grad[j] * ps.matrix[j, i] for j in range(n)) if t != 0] for i in range(n)]


def _prove_casimir(ps: PoissonStructure, C: sp.Expr, max_ops: int = MAX_PROOF_OPS) -> tuple[bool | None, str]:
    undecided = []
    for xi, terms in zip(ps.variables, casimir_brackets(ps, C)):
        verdict, detail = _vanishes(sp.Add(*terms), max_ops)
        if verdict is False:
            return False, f"{{C, {xi}}} {detail}"
        if verdict is None:
            undecided.append(f"{{C, {xi}}}: {detail}")
    if undecided:
        return None, "; ".join(undecided)
    return True, "{C, x_i} reduces to 0 for every i, parameters symbolic"


def _casimir_task(ps: PoissonStructure, C: sp.Expr, limits: WorkLimits) -> tuple[tuple, Callable[..., Any], tuple]:
    C = sp.sympify(C)
    return ("casimir", C, limits.max_proof_ops) + _key(ps), _prove_casimir, (ps, C, limits.max_proof_ops)


def casimir_symbolic(ps: PoissonStructure, C: sp.Expr,
                     limits: WorkLimits = work_limits.DEFAULT) -> tuple[bool | None, str]:
    """Whether ``{C, x_i} ≡ 0`` for every i (run to its end in a thread of its own, cached); each
    ``{C, x_i}`` is tried when it has at most ``limits.max_proof_ops`` sympy operations.

    Raises
    ------
    nonholonomic.bounded.SafetyCapExceeded
        If the proof outlives the service's safety cap (a failure, not a verdict).
    """
    return bounded.prove(*_casimir_task(ps, C, limits))


def _start_casimirs(ps: PoissonStructure, candidates: Sequence[sp.Expr], limits: WorkLimits) -> None:
    """Start the Casimir proofs at once, each in its own thread (they run side by side)."""
    for C in candidates:
        bounded.start(*_casimir_task(ps, C, limits))


def casimir_checks(ps: PoissonStructure,
                   limits: WorkLimits = work_limits.DEFAULT) -> list[tuple[str, bool | None, str]]:
    """For each claimed Casimir ``C`` in ``ps.casimirs``: ``(name, verdict, detail)`` of ``{C, x_i} ≡ 0 ∀ i``
    (the proofs run side by side, each to its end; ``limits`` as in :func:`casimir_symbolic`)."""
    _start_casimirs(ps, [C for _, C in ps.casimirs], limits)
    return [(name, *casimir_symbolic(ps, C, limits)) for name, C in ps.casimirs]


@lru_cache(maxsize=256)
def _casimir_kernel(ps: PoissonStructure, C: sp.Expr) -> _GroupedSums:
    return _GroupedSums(casimir_brackets(ps, C), ps.variables + ps.parameters)


def casimir_pointwise(ps: PoissonStructure, C: sp.Expr, points: np.ndarray,
                      parameters: np.ndarray | None = None) -> float:
    """``max over points and i of |{C, x_i}| / Σ_j |∂_j C P_ji|`` (NaN if no point is finite)."""
    return _max_residual(_casimir_kernel(ps, sp.sympify(C)), _points(ps, points), _parameter_vector(ps, parameters))


# --------------------------------------------------------------------------------------------
# Rank
# --------------------------------------------------------------------------------------------

def _ranks(ps: PoissonStructure, X: np.ndarray, p: np.ndarray) -> list[int | None]:
    n = len(ps.variables)
    with np.errstate(all="ignore"):
        mats = _matrix_kernel(ps)(X, p).reshape(-1, n, n)
    out: list[int | None] = []
    for m in mats:
        if not np.all(np.isfinite(m)):
            out.append(None)
            continue
        s = np.linalg.svd(m, compute_uv=False)
        out.append(int(np.sum(s > RANK_RTOL * s[0])) if s[0] > 0 else 0)
    return out


def rank_at(ps: PoissonStructure, point: np.ndarray, parameters: np.ndarray | None = None) -> int:
    """Numeric rank of ``P`` at ``point``: singular values above ``RANK_RTOL · σ_max``.

    Raises
    ------
    ValueError
        If the matrix is not finite at the point (a pole of the bracket).
    """
    rank = _ranks(ps, _points(ps, point), _parameter_vector(ps, parameters))[0]
    if rank is None:
        raise ValueError(f"{ps.name}: the Poisson matrix is not finite at {np.asarray(point).tolist()}")
    return rank


# --------------------------------------------------------------------------------------------
# Evidence for a catalogued structure
# --------------------------------------------------------------------------------------------

def structure_evidence(ps: PoissonStructure, points: np.ndarray, parameters: np.ndarray | None = None,
                       limits: WorkLimits = work_limits.DEFAULT) -> list[CheckEvidence]:
    """Symbolic and pointwise evidence that ``ps`` is a Poisson structure with the claimed Casimirs.

    Items: ``jacobi_identity`` (methods ``symbolic`` and ``pointwise``, tolerance 1e-10), one
    ``casimir`` per claimed Casimir (verdict symbolic; residual the pointwise
    ``max |{C, x_i}| / Σ_j |∂_j C P_ji|`` at ``points``; if the proof is undecided a residual above
    1e-6 counts as a disproof) and ``rank_on_leaf`` (numeric rank at ``points``: passed iff it is
    the same at every point and even, as the rank of a Poisson tensor on a symplectic leaf must be).
    ``limits`` bounds the size of what the symbolic proofs are tried on (:func:`jacobi_symbolic`).
    """
    X = _points(ps, points)
    p = _parameter_vector(ps, parameters)
    _start_casimirs(ps, [C for _, C in ps.casimirs], limits)  # alongside the Jacobi proof
    proven, detail = jacobi_symbolic(ps, limits)
    residual = jacobi_pointwise(ps, X, p)
    items = [
        CheckEvidence(
            name="jacobi_identity", quantity="J_ijk = {x_i, {x_j, x_k}} + cycl. for i<j<k", formula=ps.formula,
            equation=ps.equation, method="symbolic", residual=0.0 if proven else None, tolerance=0.0,
            passed=proven, detail=detail,
        ),
        CheckEvidence(
            name="jacobi_identity", quantity="J_ijk = {x_i, {x_j, x_k}} + cycl. for i<j<k", formula=ps.formula,
            equation=ps.equation, method="pointwise", residual=residual, tolerance=POINTWISE_TOLERANCE,
            passed=bool(np.isfinite(residual) and residual <= POINTWISE_TOLERANCE),
            detail=f"max over {len(X)} points and i<j<k of |J_ijk| / sum |P_il d_l P_jk + cycl. terms|, "
                   "derivatives exact (symbolic, compiled)",
        ),
    ]
    for name, C in ps.casimirs:
        verdict, cdetail = casimir_symbolic(ps, C, limits)
        res = casimir_pointwise(ps, C, X, p)
        if verdict is None and np.isfinite(res) and res > POINTWISE_DISPROOF:
            verdict, cdetail = False, cdetail + f"; pointwise residual {res:.3g} > {POINTWISE_DISPROOF:g} disproves it"
        items.append(CheckEvidence(
            name="casimir", quantity="{C, x_i} for all i", formula=ps.formula, equation=ps.equation,
            method="symbolic", residual=res, tolerance=POINTWISE_TOLERANCE, passed=verdict,
            detail=f"C = {name}: {cdetail}; pointwise max |{{C, x_i}}| / sum_j |d_j C P_ji| = {res:.3g} "
                   f"over {len(X)} points",
        ))
    ranks = _ranks(ps, X, p)
    counts = Counter(r for r in ranks if r is not None)
    constant_even = len(counts) == 1 and next(iter(counts)) % 2 == 0
    items.append(CheckEvidence(
        name="rank_on_leaf", quantity="rank of P_ij = {x_i, x_j}", formula=ps.formula, equation=ps.equation,
        method="numeric", residual=None, tolerance=RANK_RTOL, passed=constant_even,
        detail="rank " + ", ".join(f"{r} at {c} points" for r, c in sorted(counts.items()))
               + (f", not finite at {ranks.count(None)} points" if None in ranks else "")
               + f" (of {len(X)}; singular values > {RANK_RTOL:g} sigma_max); "
               + ("constant and even" if constant_even else "not constant or odd"),
    ))
    return items


# --------------------------------------------------------------------------------------------
# A user's bracket
# --------------------------------------------------------------------------------------------

def _json_float(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def _short(expr: sp.Expr, limit: int = 200) -> str:
    s = str(expr)
    return s if len(s) <= limit else s[:limit] + "..."


def _prove_antisymmetry(P: sp.Matrix, names: Sequence[str],
                        max_ops: int = MAX_PROOF_OPS) -> tuple[bool | None, str, list[dict]]:
    offending: list[dict] = []
    undecided: list[dict] = []
    for i in range(P.rows):
        for j in range(i, P.cols):
            verdict, _ = _vanishes(P[i, j] + P[j, i], max_ops)
            if verdict is not True:
                entry = {"entry": [i, j], "bracket": f"{{{names[i]}, {names[j]}}} + {{{names[j]}, {names[i]}}}",
                         "sum": _short(sp.expand(P[i, j] + P[j, i])),
                         "status": "non-zero" if verdict is False else "undecided"}
                (offending if verdict is False else undecided).append(entry)
    if offending:
        return False, f"{len(offending)} entries with P_ij + P_ji != 0", offending
    if undecided:
        return None, f"{len(undecided)} entries undecided", undecided
    return True, "P_ij + P_ji reduces to 0 for all i <= j", []


def verify_user_bracket(variables: Sequence[sp.Symbol], matrix: sp.Matrix,
                        casimir_candidates: Mapping[str, sp.Expr] | None = None,
                        parameters: Mapping[sp.Symbol, float] | None = None,
                        limits: WorkLimits = work_limits.DEFAULT, samples: int = 20, seed: int = 0) -> dict:
    """Check a user's bracket ``P_ij = {x_i, x_j}``: antisymmetry, Jacobi, Casimir candidates, rank.

    Parameters
    ----------
    variables : the coordinates ``x_1..x_n`` (sympy symbols).
    matrix : ``n × n`` sympy matrix of ``{x_i, x_j}``.
    casimir_candidates : name → C; checked by ``{C, x_i} ≡ 0`` for all i.
    parameters : values of the other symbols; substituted as exact decimals (0.1 → 1/10).
    limits : the symbolic checks are tried on expressions of at most ``limits.max_proof_ops`` sympy
        operations each (:mod:`nonholonomic.work_limits`); an undecided check falls back to pointwise,
        its detail saying why. Every proof runs to its end; the answer is the same on every machine.
    samples, seed : random points, each variable uniform in [-2, 2].

    Returns
    -------
    dict (JSON-serializable)
        ``{"dimension", "antisymmetric": {"passed", "method", "residual", "offending", "detail"},
        "jacobi": {"method", "passed", "residual", "detail"},
        "casimirs": [{"name", "method", "passed", "residual", "detail"}],
        "rank": {"values", "generic"}}``. Residuals are the pointwise relative residuals
        (``|Σ terms| / Σ |terms|``, max over the sample points) whatever decided the verdict;
        a pointwise verdict accepts up to 1e-10. ``rank.generic`` is the largest rank seen.

    Raises
    ------
    ValueError
        For a non-square matrix, a size different from the number of variables (or above
        ``MAX_USER_DIMENSION``), repeated or non-symbol variables, a non-numeric parameter value,
        a free symbol that is neither a variable nor a given parameter, or an undefined function.
    nonholonomic.bounded.SafetyCapExceeded
        If a proof outlives the service's safety cap (a failure, not a verdict).
    """
    variables = tuple(variables)
    matrix = sp.Matrix(matrix)
    if matrix.rows != matrix.cols:
        raise ValueError(f"the bracket matrix must be square, got {matrix.rows} x {matrix.cols}")
    if matrix.rows != len(variables):
        raise ValueError(f"the bracket matrix is {matrix.rows} x {matrix.cols} but there are {len(variables)} "
                         "variables")
    if not all(isinstance(v, sp.Symbol) for v in variables) or len(set(variables)) != len(variables):
        raise ValueError("variables must be distinct sympy symbols")
    if not 1 <= len(variables) <= MAX_USER_DIMENSION:
        raise ValueError(f"the bracket must have between 1 and {MAX_USER_DIMENSION} variables, got {len(variables)}")
    if samples < 1:
        raise ValueError(f"samples must be at least 1, got {samples}")
    values = {}
    for s, v in (parameters or {}).items():
        sym = s if isinstance(s, sp.Symbol) else sp.Symbol(str(s))
        try:
            value = float(v)
        except (TypeError, ValueError):
            raise ValueError(f"parameter {sym} must be a number, got {v!r}") from None
        if not np.isfinite(value):
            raise ValueError(f"parameter {sym} must be finite, got {v}")
        values[sym] = sp.Rational(repr(value))
    # Match given parameters by name too (a symbol with assumptions is another symbol to sympy).
    by_name = {str(s): val for s, val in values.items()}
    candidates = {name: sp.sympify(C) for name, C in (casimir_candidates or {}).items()}

    def substitute(e: sp.Expr) -> sp.Expr:
        # Given parameters and float literals become exact decimals, so cancellations are exact.
        e = sp.sympify(e)
        e = e.xreplace({s: by_name[str(s)] for s in e.free_symbols if s not in variables and str(s) in by_name})
        return e.xreplace({f: sp.Rational(repr(float(f))) for f in e.atoms(sp.Float)})

    P = matrix.applyfunc(substitute)
    candidates = {name: substitute(C) for name, C in candidates.items()}
    free = set(P.free_symbols).union(*(C.free_symbols for C in candidates.values())) - set(variables)
    if free:
        raise ValueError("free symbols that are neither variables nor given parameters: "
                         + ", ".join(sorted(map(str, free))))
    undefined = set(P.atoms(AppliedUndef)).union(*(C.atoms(AppliedUndef) for C in candidates.values()))
    if undefined:
        raise ValueError("undefined functions (give them explicitly): " + ", ".join(sorted(map(str, undefined))))

    n = len(variables)
    names = [str(v) for v in variables]
    ps = PoissonStructure("user", "user", variables, P, casimirs=tuple(candidates.items()),
                          formula="user bracket")
    X = np.random.default_rng(seed).uniform(-2.0, 2.0, (samples, n))
    p = np.zeros(0)

    # Start every proof at once: they run side by side, each to its end.
    antisymmetry = (("antisymmetry", limits.max_proof_ops) + _key(ps), _prove_antisymmetry,
                    (P, tuple(names), limits.max_proof_ops))
    bounded.start(*antisymmetry)
    bounded.start(*_jacobi_task(ps, limits))
    _start_casimirs(ps, list(candidates.values()), limits)

    # Antisymmetry.
    verdict, detail, offending = bounded.verdict(bounded.run(*antisymmetry))
    anti_res = _max_residual(_GroupedSums([[P[i, j], P[j, i]] for i in range(n) for j in range(i, n)], variables),
                             X, p)
    method = "symbolic"
    if verdict is None:
        method, verdict = "pointwise", bool(np.isfinite(anti_res) and anti_res <= POINTWISE_TOLERANCE)
        detail = f"{detail}; pointwise max |P_ij + P_ji| / (|P_ij| + |P_ji|) = {anti_res:.3g}"
    antisymmetric = {"passed": verdict, "method": method, "residual": _json_float(anti_res),
                     "offending": list(offending or []), "detail": detail}

    # Jacobi.
    verdict, detail = jacobi_symbolic(ps, limits)
    jac_res = jacobi_pointwise(ps, X)
    finite = int(np.sum(_jacobi_kernel(ps).residuals(X, p)[1]))
    method = "symbolic"
    if verdict is None:
        method = "pointwise"
        verdict = bool(np.isfinite(jac_res) and jac_res <= POINTWISE_TOLERANCE)
        detail = (f"symbolic check undecided ({detail}); max |J_ijk| / sum |terms| = {jac_res:.3g} at {finite} "
                  f"of {samples} random points in [-2, 2]^{n}")
    else:
        detail += f"; pointwise max |J_ijk| / sum |terms| = {jac_res:.3g} at {finite} random points"
    if antisymmetric["passed"] is False:
        detail += "; note: the matrix is not antisymmetric, so this is not a Poisson bracket anyway"
    jacobi = {"method": method, "passed": verdict, "residual": _json_float(jac_res), "detail": detail}

    # Casimir candidates.
    casimirs = []
    for name, C in candidates.items():
        verdict, detail = casimir_symbolic(ps, C, limits)
        res = casimir_pointwise(ps, C, X)
        method = "symbolic"
        if verdict is None:
            method = "pointwise"
            verdict = bool(np.isfinite(res) and res <= POINTWISE_TOLERANCE)
            detail = f"symbolic check undecided ({detail}); pointwise residual {res:.3g}"
        casimirs.append({"name": name, "method": method, "passed": verdict, "residual": _json_float(res),
                         "detail": detail})

    ranks = [r for r in _ranks(ps, X, p) if r is not None]
    return {
        "dimension": n,
        "antisymmetric": antisymmetric,
        "jacobi": jacobi,
        "casimirs": casimirs,
        "rank": {"values": ranks, "generic": max(ranks) if ranks else None},
    }
