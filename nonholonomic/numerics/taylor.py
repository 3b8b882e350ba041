"""heyoka expressions generated from a system's one symbolic definition.

Every heyoka integrator of the core (single trajectories, batch mode, Poincaré events, variational
equations) is built from :func:`taylor_system`, so the right-hand side is written once, in sympy,
in the system's module. State symbols become heyoka variables (``M1`` ... in the order of
``system.state_symbols``), then ``tau`` when the system has a regular reduced time (``taylor_time_density``);
parameters become runtime parameters ``hy.par[i]``, so one compiled integrator serves every parameter value.

The Taylor integrator evaluates the right-hand side once per Taylor order and step, so every
elementary operation it contains is paid ~20 times per step. The translation therefore removes
the redundant work a literal transcription of the sympy tree would keep (generic, no per-system
code):

1. common subexpressions of all the components together (and of the τ density) are found once
   (``sympy.cse``); the sums among them (e.g. ω = I_Q⁻¹ M, the Sherman–Morrison denominator
   ``1 − D (γ, J⁻¹γ)``) become shared intermediates;
2. each sum is expanded into monomials of the state, the intermediates and the parameters, then
   refactored greedily (a multivariate Horner scheme: the factor common to most monomials is
   taken out together with the whole common content of its group), which recovers shared
   factors such as the Sherman–Morrison rank-one term ``D (J⁻¹γ, M) / (1 − D (γ, J⁻¹γ))``;
3. every parameter-only factor (``1/(I1 + D)``, ``det J^(−1/2)``, ``D/(I2 + D)²`` ...) is hoisted
   out of the ODE into a *derived runtime parameter*, computed once per run from the user's
   parameters by :meth:`TaylorSystem.runtime_parameters`.

The sympy tree as written (steps 1 and 3 without the expansion of step 2) is kept as a second
candidate and the one with fewer operations wins. :attr:`TaylorSystem.operations` counts them
(heyoka's decomposition shares equal subexpressions the same way and finds the same number
or a few fewer): 85 → 46 for Chaplygin's ball (44 written by hand).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import TypedDict

import heyoka as hy
import numpy as np
import sympy as sp

from nonholonomic import memo
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.numpy_function import lambdify_numpy

#: A sum whose expansion has more monomials than this keeps the structure it was written in.
MAX_EXPANDED_TERMS = 400

#: A monomial: its coefficient (a number times parameters) and ``{non-parameter symbol: rational exponent}``.
Term = tuple[sp.Expr, dict[sp.Expr, sp.Expr]]


@dataclass(frozen=True, eq=False)
class TaylorSystem:
    """The heyoka form of one :class:`MechanicalSystem`.

    Attributes
    ----------
    system : the symbolic definition it was generated from.
    variables : heyoka variables, the state symbols' names in order, then ``tau`` if ``has_tau``.
    rhs : ``d/dt`` of each variable (same order).
    n_state : number of state variables (``system.dimension``).
    has_tau : whether the reduced time τ is integrated as the last variable.
    n_pars : length of heyoka's runtime parameter vector: the system's parameters (in the order of
        ``system.parameter_symbols``, so ``hy.par[i]`` is still the i-th one), then the derived
        parameters hoisted out of the right-hand side (see :meth:`runtime_parameters`).
    derived_parameters : the derived parameters as sympy expressions in the system's parameters.
    operations : elementary operations of the right-hand side as generated (distinct heyoka
        nodes; heyoka's own count is ``len(ta.decomposition) - 2 * len(variables)``).
    strategy : ``"horner"`` (cse, expansion and refactoring) or ``"direct"`` (the sympy tree as
        written, parameter-only parts hoisted), whichever needs fewer operations.
    """

    system: MechanicalSystem
    variables: tuple[hy.expression, ...]
    rhs: tuple[hy.expression, ...]
    n_state: int
    has_tau: bool
    n_pars: int
    derived_parameters: tuple[sp.Expr, ...]
    operations: int
    strategy: str
    _derived: Callable[..., list[object]] | None = field(repr=False)
    _parameters: _Parameters = field(repr=False)

    @property
    def equations(self) -> list[tuple[hy.expression, hy.expression]]:
        """``[(variable, rhs), ...]`` as heyoka's integrators take them."""
        return list(zip(self.variables, self.rhs))

    @property
    def state_equations(self) -> list[tuple[hy.expression, hy.expression]]:
        """The state's equations without τ (for variational equations)."""
        return list(zip(self.variables[: self.n_state], self.rhs[: self.n_state]))

    @property
    def n_user_pars(self) -> int:
        """Number of the system's own parameters (the first entries of the runtime vector)."""
        return len(self.system.parameter_symbols)

    def runtime_parameters(self, parameters: np.ndarray) -> np.ndarray:
        """heyoka's parameter vector from the system's parameters (order of ``system.parameter_symbols``).

        Works on one vector (shape ``(n,)``) or on a batch (shape ``(n, batch)``, one column per
        member); returns shape ``(n_pars,)`` or ``(n_pars, batch)``: the parameters themselves, then
        the derived ones.

        Raises
        ------
        ValueError
            If the first axis is not the number of the system's parameters.
        """
        p = np.asarray(parameters, dtype=float)
        if p.ndim not in (1, 2) or p.shape[0] != self.n_user_pars:
            raise ValueError(f"{self.system.kind} needs {self.n_user_pars} parameters (axis 0), got shape {p.shape}")
        if self._derived is None:
            return p.copy()
        with np.errstate(all="ignore"):
            values = self._derived(*p)
        derived = np.stack([np.broadcast_to(np.asarray(v, dtype=float), p.shape[1:]) for v in values])
        return np.concatenate([p, derived], axis=0)

    def expression(self, expr: sp.Expr) -> hy.expression:
        """Translate a sympy expression in the state and parameter symbols into heyoka (e.g. an
        event's surface), through the same optimisation and hoisting as the right-hand side: a
        parameter-only part already hoisted uses its derived parameter, any other is computed from
        the system's parameters in the expression itself.

        Raises
        ------
        ValueError
            If ``expr`` has a symbol that is neither a state nor a parameter symbol.
        """
        return self.expressions([expr])[0]

    def expressions(self, exprs: Sequence[sp.Expr]) -> list[hy.expression]:
        """Translate several expressions together (their common subexpressions shared), as
        :meth:`expression` does one; e.g. the first integrals for a compiled function.

        Raises
        ------
        ValueError
            If an expression has a symbol that is neither a state nor a parameter symbol.
        """
        exprs = [sp.sympify(e) for e in exprs]
        known = set(self.system.state_symbols) | set(self.system.parameter_symbols)
        unknown = sorted({str(s) for e in exprs for s in e.free_symbols - known})
        if unknown:
            raise ValueError(f"unknown symbols {unknown} for {self.system.kind}")
        state = dict(zip(self.system.state_symbols, self.variables))
        return _translate(exprs, state, self._parameters).expressions

    def initial(self, state: Sequence[float] | np.ndarray) -> np.ndarray:
        """The integrator's initial vector from a state: the state, then τ(0) = 0 if ``has_tau``."""
        y = np.asarray(state, dtype=float)
        return np.append(y, 0.0) if self.has_tau else y.copy()


@lru_cache(maxsize=64)
def taylor_system(system: MechanicalSystem) -> TaylorSystem:
    """The heyoka form of ``system`` (once per system and process; remembered across processes when a
    memo is installed, :mod:`nonholonomic.memo`)."""
    definition = memo.key_of("definition-of", system) if memo.installed() else None
    if definition is not None:
        form = memo.remember("taylor-form", definition, lambda: _taylor_form(system))
    else:  # no memo, or a definition that does not pickle: derived here
        form = _taylor_form(system)
    return TaylorSystem(system=system, **form)


class _TaylorForm(TypedDict):
    """The fields of a :class:`TaylorSystem` but ``system`` (what :func:`_taylor_form` returns and the memo keeps)."""

    variables: tuple[hy.expression, ...]
    rhs: tuple[hy.expression, ...]
    n_state: int
    has_tau: bool
    n_pars: int
    derived_parameters: tuple[sp.Expr, ...]
    operations: int
    strategy: str
    _derived: Callable[..., list[object]] | None
    _parameters: _Parameters


def _taylor_form(system: MechanicalSystem) -> _TaylorForm:
    """Every field of the :class:`TaylorSystem` of ``system`` but the system itself (it pickles)."""
    density = system.taylor_time_density
    names = [str(s) for s in system.state_symbols] + (["tau"] if density is not None else [])
    hvars = hy.make_vars(*names)
    if len(names) == 1:
        hvars = [hvars]
    exprs = list(system.rhs) + ([density] if density is not None else [])
    state = dict(zip(system.state_symbols, hvars))
    best = _translate(exprs, state, _Parameters(system.parameter_symbols))
    derived = tuple(best.parameters.derived)
    fn = lambdify_numpy(system.parameter_symbols, derived) if derived else None
    return {"variables": tuple(hvars), "rhs": tuple(best.expressions), "n_state": system.dimension,
            "has_tau": density is not None, "n_pars": len(system.parameter_symbols) + len(derived),
            "derived_parameters": derived, "operations": best.operations, "strategy": best.strategy,
            "_derived": fn, "_parameters": best.parameters.copy(frozen=True)}


# --- parameters ------------------------------------------------------------------------------------


class _Parameters:
    """The runtime parameter vector: the system's parameters, then hoisted parameter-only parts.

    ``frozen`` tables (after compilation) hoist nothing new: an unknown parameter-only part is
    translated in the system's parameters instead.
    """

    def __init__(self, symbols: Iterable[sp.Symbol], frozen: bool = False) -> None:
        self.symbols = tuple(symbols)
        self.index = {s: i for i, s in enumerate(self.symbols)}
        self.mapping = {s: hy.par[i] for i, s in enumerate(self.symbols)}
        self.derived: list[sp.Expr] = []
        self.where: dict[sp.Expr, int] = {}
        self.frozen = frozen

    def copy(self, frozen: bool | None = None) -> _Parameters:
        """A copy (frozen or not, by default as this one)."""
        out = _Parameters(self.symbols, frozen=self.frozen if frozen is None else frozen)
        out.derived, out.where = list(self.derived), dict(self.where)
        return out

    def value(self, expr: sp.Expr) -> hy.expression:
        """The heyoka value of a parameter-only expression (in the system's parameters)."""
        if expr in self.index:
            return hy.par[self.index[expr]]
        if expr not in self.where:
            if self.frozen:
                return from_sympy(expr, self.mapping)
            self.where[expr] = len(self.symbols) + len(self.derived)
            self.derived.append(expr)
        return hy.par[self.where[expr]]


def from_sympy(expr: sp.Expr, mapping: dict[sp.Symbol, hy.expression]) -> hy.expression:
    """``hy.from_sympy`` that also knows ``Abs`` (heyoka has no |x|): each ``Abs(x)`` becomes a
    placeholder for heyoka's ``sqrt(x**2)`` (e.g. the scale ``|c|`` of an integral of Neumann's
    system; sympy itself would fold ``sqrt(x**2)`` back into ``Abs`` for a real ``x``)."""
    absolutes = {a: sp.Dummy("abs") for a in expr.atoms(sp.Abs)}
    if not absolutes:
        return hy.from_sympy(expr, mapping)
    inner = {d: hy.sqrt(from_sympy(a.args[0], mapping) ** 2) for a, d in absolutes.items()}
    return hy.from_sympy(expr.xreplace(absolutes), {**mapping, **inner})


# --- heyoka expressions with shared nodes --------------------------------------------------------


class _Emitter:
    """Builds heyoka expressions node by node, giving equal nodes one identity (as heyoka's
    decomposition will share them) and counting the distinct operations."""

    def __init__(self) -> None:
        self._ids: dict[tuple[object, ...], int] = {}
        self.exprs: list[hy.expression] = []
        self.ops = 0

    def _node(self, key: tuple[object, ...], make: Callable[[], hy.expression], op: bool = True) -> int:
        if key not in self._ids:
            self._ids[key] = len(self.exprs)
            self.exprs.append(make())
            self.ops += op
        return self._ids[key]

    def leaf(self, key: object, expr: hy.expression) -> int:
        return self._node(("leaf", key), lambda: expr, op=False)

    def const(self, value: float) -> int:
        return self._node(("const", value), lambda: hy.expression(value), op=False)

    def mul(self, a: int, b: int) -> int:
        a, b = min(a, b), max(a, b)
        return self._node(("*", a, b), lambda: self.exprs[a] * self.exprs[b])

    def div(self, a: int, b: int) -> int:
        return self._node(("/", a, b), lambda: self.exprs[a] / self.exprs[b])

    def pow(self, a: int, e: float) -> int:
        if e == 1.0:
            return a
        return self._node(("^", a, e), lambda: self.exprs[a] ** e)

    def sqrt(self, a: int) -> int:
        return self._node(("sqrt", a), lambda: hy.sqrt(self.exprs[a]))

    def power(self, a: int, e: sp.Expr) -> tuple[int, bool]:
        """``a**e`` as ``(node, is_denominator)``: a negative integer or half-integer power is
        returned as ``a**|e|`` to divide by; half-integer powers use ``sqrt`` (correctly rounded)."""
        if not e.is_Rational or (2 * e).q != 1:  # neither an integer nor a half-integer
            return self.pow(a, float(e)), False
        twice = abs(int(2 * e))
        node = self.pow(a, float(twice // 2)) if twice >= 2 else None
        if twice % 2:
            root = self.sqrt(a)
            node = root if node is None else self.mul(node, root)
        assert node is not None
        return node, bool(e < 0)

    def sum(self, terms: list[int]) -> int:
        if len(terms) == 1:
            return terms[0]
        key = tuple(sorted(terms))
        return self._node(("+", key), lambda: hy.sum([self.exprs[t] for t in key]))

    def sub(self, a: int, b: int) -> int:
        return self._node(("-", a, b), lambda: self.exprs[a] - self.exprs[b])

    def neg(self, a: int) -> int:
        return self._node(("neg", a), lambda: -self.exprs[a])

    def function(self, func: type, args: list[int]) -> int:
        def make() -> hy.expression:
            dummies = [sp.Dummy() for _ in args]
            return from_sympy(func(*dummies), {d: self.exprs[a] for d, a in zip(dummies, args)})
        return self._node(("f", str(func), tuple(args)), make)

    def product(self, factors: list[int]) -> int | None:
        """Left-to-right product (None if empty)."""
        out: int | None = None
        for f in factors:
            out = f if out is None else self.mul(out, f)
        return out


# --- the translation -------------------------------------------------------------------------------


@dataclass
class _Translation:
    expressions: list[hy.expression]
    parameters: _Parameters
    operations: int
    strategy: str


def _translate(exprs: list[sp.Expr], state: dict[sp.Symbol, hy.expression], parameters: _Parameters) -> _Translation:
    """Both strategies on ``exprs`` (each with its own copy of ``parameters``); the one with fewer operations."""
    results = []
    for strategy in ("horner", "direct"):
        table = parameters.copy()
        gen = _Generator(state, table, horner=strategy == "horner")
        out = gen.run(exprs)
        results.append(_Translation(out, table, gen.emitter.ops, strategy))
    return min(results, key=lambda r: r.operations)


class _Generator:
    """One translation of a list of expressions into shared heyoka expressions.

    Symbols are of three sorts: state symbols (heyoka variables), parameter-like symbols (the
    system's parameters and sums of them, hoisted) and intermediates (shared sums, emitted once).
    """

    def __init__(self, state: dict[sp.Symbol, hy.expression], parameters: _Parameters, horner: bool) -> None:
        self.emitter = _Emitter()
        self.parameters = parameters
        self.horner = horner
        self.state = state
        self.state_order = {s: i for i, s in enumerate(state)}
        self.param_full: dict[sp.Symbol, sp.Expr] = {}  # parameter-like symbol -> its expression
        self.bodies: dict[sp.Symbol, sp.Expr] = {}  # intermediate -> its expression
        self.emitted: dict[sp.Symbol, int] = {}
        self.atoms: dict[sp.Expr, sp.Symbol] = {}  # expression -> the symbol standing for it
        self._symbols = sp.numbered_symbols("_nh", cls=sp.Dummy)

    # -- sorts of symbols

    def is_param(self, expr: sp.Expr) -> bool:
        return expr.free_symbols <= (set(self.parameters.symbols) | set(self.param_full))

    def parameter(self, expr: sp.Expr) -> int:
        """The node of a parameter-only expression: a literal, a system parameter or a derived one."""
        full = sp.sympify(expr).xreplace(self.param_full)
        if full.is_number:
            return self.emitter.const(float(full))
        return self.emitter.leaf(("par", full), self.parameters.value(full))

    def symbol(self, s: sp.Symbol) -> int:
        if s in self.state:
            return self.emitter.leaf(s, self.state[s])
        if self.is_param(s):
            return self.parameter(s)
        if s not in self.emitted:
            self.emitted[s] = self.piece(self.bodies[s])
        return self.emitted[s]

    def atom(self, expr: sp.Expr) -> sp.Symbol:
        """The symbol standing for ``expr``: a parameter-like one if it depends on parameters only,
        else an intermediate emitted once (a sum under a negative or fractional power, a function ...)."""
        if expr not in self.atoms:
            s = next(self._symbols)
            self.atoms[expr] = s
            if self.is_param(expr):
                self.param_full[s] = expr.xreplace(self.param_full)
            else:
                self.bodies[s] = expr
        return self.atoms[expr]

    # -- driver

    def run(self, exprs: list[sp.Expr]) -> list[hy.expression]:
        """Common subexpressions of all ``exprs``, then each one emitted."""
        replacements, reduced = sp.cse(exprs, symbols=self._symbols)
        inline: dict[sp.Symbol, sp.Expr] = {}
        for s, body in replacements:
            body = body.xreplace(inline)
            if _is_monomial(body) or (self.is_param(body) and (body.is_Mul or body.is_Pow)):
                inline[s] = body  # products are refactored where they are used
            elif self.is_param(body):
                self.param_full[s] = body.xreplace(self.param_full)
            else:
                self.bodies[s] = body
        return [self.emitter.exprs[self.piece(e.xreplace(inline))] for e in reduced]

    def piece(self, expr: sp.Expr) -> int:
        """Emit one expression (a component or an intermediate's body)."""
        if self.is_param(expr):
            return self.parameter(expr)
        if expr.is_Symbol:
            return self.symbol(expr)
        if not self.horner:
            return self.direct(expr)
        if not (expr.is_Add or expr.is_Mul or expr.is_Pow) or (expr.is_Pow and not expr.exp.is_number):
            return self.function(expr)
        expanded = sp.expand(self.prepare(expr))
        monomials = sp.Add.make_args(expanded)
        if len(monomials) > MAX_EXPANDED_TERMS:
            return self.direct(expr)
        terms: dict[frozenset[tuple[sp.Expr, sp.Expr]], list[sp.Expr]] = {}
        for m in monomials:  # like terms (same non-parameter factors): one parameter coefficient
            coeff, factors = self.term(m)
            terms.setdefault(frozenset(factors.items()), []).append(coeff)
        merged = [(sp.Add(*c), dict(k)) for k, c in terms.items()]
        merged = [t for t in merged if t[0] != 0] or [(sp.Integer(0), {})]
        sign, node = self.emit(_horner(merged))
        return self.emitter.neg(node) if sign < 0 else node

    # -- direct strategy: the tree as written, parameter-only parts hoisted

    def direct(self, expr: sp.Expr) -> int:
        if self.is_param(expr):
            return self.parameter(expr)
        if expr.is_Symbol:
            return self.symbol(expr)
        if expr.is_Add:
            params = [a for a in expr.args if self.is_param(a)]
            pos: list[int] = []
            neg: list[int] = []
            for a in expr.args:
                if not self.is_param(a):
                    minus = a.could_extract_minus_sign()
                    (neg if minus else pos).append(self.direct(-a if minus else a))
            if params:
                pos.append(self.parameter(sp.Add(*params)))
            return _combine(self.emitter, pos, neg)
        if expr.is_Mul:
            coeff = sp.Mul(*[a for a in expr.args if self.is_param(a)])
            num: list[int] = []
            den: list[int] = []
            for a in expr.args:
                if self.is_param(a):
                    continue
                base, e = a.as_base_exp()
                if e.is_Rational and e < 0:
                    node, divide = self.emitter.power(self.direct(base), e)
                    (den if divide else num).append(node)
                else:
                    num.append(self.direct(a))
            if coeff != 1:
                num.insert(0, self.parameter(coeff))
            out = self.emitter.product(num)
            if den:
                d = self.emitter.product(den)
                assert d is not None
                out = self.emitter.div(self.emitter.const(1.0), d) if out is None else self.emitter.div(out, d)
            assert out is not None
            return out
        if expr.is_Pow and expr.exp.is_number:
            node, divide = self.emitter.power(self.direct(expr.base), expr.exp)
            return self.emitter.div(self.emitter.const(1.0), node) if divide else node
        return self.function(expr)

    def function(self, expr: sp.Expr) -> int:
        return self.emitter.function(expr.func, [self.piece(a) for a in expr.args])

    # -- horner strategy

    def prepare(self, expr: sp.Expr) -> sp.Expr:
        """``expr`` with a symbol for every parameter-only sum or function and for every
        non-symbol base that expanding must not multiply out (negative or fractional powers)."""
        if expr.is_Atom:
            return expr
        if self.is_param(expr) and not (expr.is_Mul or expr.is_Pow):
            return self.atom(expr)
        if expr.is_Pow:
            base, e = expr.args
            if e.is_Integer and e > 0 or base.is_Symbol and e.is_number:
                return sp.Pow(self.prepare(base), e)
            return sp.Pow(self.atom(base), e) if e.is_number else self.atom(expr)
        if expr.is_Add or expr.is_Mul:
            return expr.func(*[self.prepare(a) for a in expr.args])
        return self.atom(expr)

    def term(self, monomial: sp.Expr) -> Term:
        """``(parameter coefficient, {non-parameter symbol: rational exponent})`` of a monomial."""
        coeff, rest = monomial.as_coeff_Mul()
        params: list[sp.Expr] = [coeff]
        factors: dict[sp.Expr, sp.Expr] = {}
        for base, e in rest.as_powers_dict().items():
            if self.is_param(base) and self.is_param(e):
                params.append(base**e)
                continue
            if not e.is_Rational:
                base, e = self.atom(base**e), sp.Integer(1)
            elif not base.is_Symbol:
                base = self.atom(base)
            factors[base] = factors.get(base, sp.Integer(0)) + e
        return sp.Mul(*params), {b: e for b, e in factors.items() if e != 0}

    def emit(self, node: _Node) -> tuple[int, int]:
        """``(sign, node id)`` of a Horner node."""
        if isinstance(node, list):  # a sum
            pos: list[int] = []
            neg: list[int] = []
            for child in node:
                sign, i = self.emit(child)
                (pos if sign > 0 else neg).append(i)
            if not pos:
                return -1, self.emitter.sum(neg)
            return 1, _combine(self.emitter, pos, neg)
        coeff, factors, cofactor = node
        sign = -1 if coeff.could_extract_minus_sign() else 1
        coeff = -coeff if sign < 0 else coeff
        inter = sorted((b for b in factors if b not in self.state), key=sp.default_sort_key)
        states = sorted((b for b in factors if b in self.state), key=lambda s: self.state_order[s])
        # Order: the cofactor (a sum, maybe shared), intermediates and their denominators, the
        # parameter, the state; so products common to several components are a common prefix.
        chain: int | None = None
        if cofactor is not None:
            csign, chain = self.emit(cofactor)
            sign *= csign
        pending: list[int] = []  # denominators, divided out as soon as there is a numerator

        def times(factor: int) -> None:
            nonlocal chain, pending
            chain = factor if chain is None else self.emitter.mul(chain, factor)
            flush()

        def flush() -> None:
            nonlocal chain, pending
            if pending and chain is not None:
                d = self.emitter.product(pending)
                assert d is not None
                chain, pending = self.emitter.div(chain, d), []

        def power(b: sp.Expr) -> None:
            node, divide = self.emitter.power(self.symbol(b), factors[b])
            if divide:
                pending.append(node)
            else:
                times(node)

        for b in inter:
            power(b)
        flush()
        if coeff != 1:
            times(self.parameter(coeff))
        for b in states:
            power(b)
        if pending:
            d = self.emitter.product(pending)
            assert d is not None
            chain = self.emitter.div(self.emitter.const(1.0), d) if chain is None else self.emitter.div(chain, d)
        if chain is None:
            chain = self.emitter.const(float(coeff)) if coeff.is_number else self.parameter(coeff)
        return sign, chain


#: A Horner node: a list (a sum of nodes) or ``(coefficient, factors, cofactor node or None)``.
_Node = list | tuple


def _is_monomial(expr: sp.Expr) -> bool:
    """A product of numbers and powers of symbols (refactored where it is used, not shared)."""
    if not (expr.is_Mul or expr.is_Pow):
        return False
    return all(f.is_number or f.is_Symbol or (f.is_Pow and f.base.is_Symbol and f.exp.is_number)
               for f in sp.Mul.make_args(expr))


def _combine(emitter: _Emitter, pos: list[int], neg: list[int]) -> int:
    """``Σ pos − Σ neg`` with one subtraction (or a negation if there is nothing positive)."""
    if not neg:
        return emitter.sum(pos)
    if not pos:
        return emitter.neg(emitter.sum(neg))
    return emitter.sub(emitter.sum(pos), emitter.sum(neg))


def _powers(coeff: sp.Expr) -> tuple[sp.Expr, dict[sp.Expr, sp.Expr]]:
    """A parameter coefficient as ``(number, {base: exponent})``."""
    number, rest = coeff.as_coeff_Mul()
    return number, {b: e for b, e in rest.as_powers_dict().items() if not b.is_number}


def _common_powers(dicts: list[dict[sp.Expr, sp.Expr]]) -> dict[sp.Expr, sp.Expr]:
    """Bases present in every dict with exponents of one sign, at the smallest magnitude."""
    common: dict[sp.Expr, sp.Expr] = {}
    for b, e in dicts[0].items():
        exps = [d.get(b) for d in dicts]
        if all(x is not None and x.is_number and e.is_number and bool(x > 0) == bool(e > 0) for x in exps):
            common[b] = min((x for x in exps if x is not None), key=abs)  # none is None (checked just above)
    return common


def _common(terms: list[Term]) -> Term:
    """The common content of monomials: non-parameter factors and parameter factors they all
    have, and the numeric coefficient's magnitude if they all share it."""
    powers = [_powers(c) for c, _ in terms]
    numbers = {abs(n) for n, _ in powers}
    number = numbers.pop() if len(numbers) == 1 else sp.Integer(1)
    coeff = sp.Mul(number, *[b**e for b, e in _common_powers([p for _, p in powers]).items()])
    return coeff, _common_powers([f for _, f in terms])


def _divide(t: Term, g: Term) -> Term:
    factors = dict(t[1])
    for b, e in g[1].items():
        factors[b] = factors[b] - e
    return t[0] / g[0], {b: e for b, e in factors.items() if e != 0}


def _horner(terms: list[Term]) -> _Node:
    """Greedy multivariate Horner form of a sum of monomials.

    Take out the content common to all terms; otherwise split off the group of terms sharing the
    factor (base and sign of its exponent) present in most terms, whose own common content is then
    taken out, recursively.
    """
    if len(terms) == 1:
        return (terms[0][0], terms[0][1], None)
    g = _common(terms)
    if g[1] or g[0] != 1:
        return (g[0], g[1], _horner([_divide(t, g) for t in terms]))
    counts: dict[tuple[sp.Expr, bool], int] = {}
    for _, factors in terms:
        for b, e in factors.items():
            counts[(b, bool(e > 0))] = counts.get((b, bool(e > 0)), 0) + 1
    if not counts or max(counts.values()) < 2:
        return [(c, f, None) for c, f in terms]
    best = max(counts, key=lambda k: (counts[k], k[1], sp.default_sort_key(k[0])))

    def in_group(t: Term) -> bool:
        return best[0] in t[1] and bool(t[1][best[0]] > 0) == best[1]

    out: list[_Node] = [_horner([t for t in terms if in_group(t)])]
    rest = [t for t in terms if not in_group(t)]
    if rest:
        r = _horner(rest)
        out.extend(r if isinstance(r, list) else [r])
    return out
