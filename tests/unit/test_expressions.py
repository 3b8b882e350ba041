"""The safe expression parser: exact round trips, refusals with positions, resource guards, no eval."""

from __future__ import annotations

import io
import math
import pickle
import tokenize
from pathlib import Path

import pytest
import sympy as sp
from hypothesis import HealthCheck, assume, given, settings, strategies as st

from nonholonomic import expressions as ex
from nonholonomic.expressions import (
    ALLOWED_FUNCTIONS,
    ExpressionError,
    declare_symbols,
    parse_expression,
    parse_matrix,
)
from nonholonomic.hamiltonization.poisson import chaplygin_ball_bracket, e3
from tests.support import hang_guard

NAMES = ["I1", "I2", "I3", "theta", "phi", "thetadot", "phidot", "x", "y", "z", "e", "E1", "E2"]
S = declare_symbols(NAMES)
I1, I2, I3, theta, phi, thetadot, phidot, x, y, z, e_var, E1, E2 = (S[n] for n in NAMES)
#: Hang guards, not results (speed is measured in bench/): a refusal (measured: < 1 ms each) or fuzzed
#: parse still running after this many seconds is interrupted (:func:`tests.support.hang_guard`).
FAST_S = 5.0
#: The slowest accepted 2000-character inputs (measured cold: 0.21-0.56 s on 2 quiet cores, 2.8 s at load
#: 16): a hang guard, 100 times the quiet time.
WORST_S = 60.0


def parse(text: str, **kw) -> sp.Expr:
    return parse_expression(text, S, **kw)


def refuse(text: str, **kw) -> ExpressionError:
    with hang_guard(FAST_S, f"refusing {text[:40]!r}"), pytest.raises(ExpressionError) as info:
        parse(text, **kw)
    return info.value


# --- accepted expressions: exact round trips ------------------------------------------------------

@pytest.mark.parametrize("text, expected", [
    ("1/2*I1*thetadot**2", sp.Rational(1, 2) * I1 * thetadot**2),
    ("1/2*(I1*thetadot**2 + sin(theta)**2*phidot**2)",
     sp.Rational(1, 2) * (I1 * thetadot**2 + sp.sin(theta)**2 * phidot**2)),
    ("x*y - z", x * y - z),                         # a bracket entry
    ("2.5*x", sp.Rational(5, 2) * x),               # decimal literals are exact
    ("0.1 + 0.2", sp.Rational(3, 10)),              # 0.30000000000000004 in floats
    ("1e-3*x", x / 1000),
    ("1_000.5", sp.Rational(2001, 2)),
    ("0x1F*x", 31 * x),
    ("-x**2", -(x**2)),                             # ** binds tighter than unary minus
    ("(-x)**2", x**2),
    ("2**-1", sp.Rational(1, 2)),
    ("x**y**2", x**(y**2)),                         # ** is right-associative
    ("x/y/z", x / (y * z)),                         # / is left-associative
    ("x - y - z", x - y - z),
    ("-2*x**2/3 + +x", -sp.Rational(2, 3) * x**2 + x),
    ("x**(1/3)", x**sp.Rational(1, 3)),
    ("x**0.5", sp.sqrt(x)),
    ("x**-64", x**-64),
    ("atan2(y, x)", sp.atan2(y, x)),
    ("abs(x) + sign(y)", sp.Abs(x) + sp.sign(y)),
    ("sqrt(x**2)", sp.Abs(x)),                      # declared symbols are real
    ("exp(1)", sp.E),
    ("log(E)", sp.Integer(1)),
    ("pi/2", sp.pi / 2),
    ("asin(1)", sp.pi / 2),
    ("sec(x)*csc(y)*cot(z)*tan(x)", sp.sec(x) * sp.csc(y) * sp.cot(z) * sp.tan(x)),
    ("asin(x) + acos(y) + atan(z)", sp.asin(x) + sp.acos(y) + sp.atan(z)),
    ("sinh(x) + cosh(y) + tanh(z)", sp.sinh(x) + sp.cosh(y) + sp.tanh(z)),
    ("e*E1 + E2", e_var * E1 + E2),                 # e, E1, E2 are user variables; E is Euler's number
    ("x +\n\ty", x + y),                            # newlines/tabs are whitespace
    ("x**64", x**64),
])
def test_round_trip_is_exact(text, expected):
    got = parse(text)
    assert got == expected  # structural equality, no simplification needed
    assert isinstance(got, sp.Expr)


def test_trig_identity_and_real_symbols():
    got = parse("sin(theta)**2 + cos(theta)**2")
    assert got != 1 and sp.trigsimp(got) == 1
    assert all(s.is_real for s in parse("x*y + theta").free_symbols)
    assert parse("x") is S["x"]


def test_e3_bracket_matrix_matches_library():
    """The e(3) Poisson matrix (eq. 2504-10-2) typed as a user would: equal to brackets.e3() exactly."""
    P = e3()
    names = [str(v) for v in P.variables]
    syms = declare_symbols(names)
    rows = [["0", "M3", "-M2", "0", "Gamma3", "-Gamma2"],
            ["-M3", "0", "M1", "-Gamma3", "0", "Gamma1"],
            ["M2", "-M1", "0", "Gamma2", "-Gamma1", "0"],
            ["0", "Gamma3", "-Gamma2", "0", "0", "0"],
            ["-Gamma3", "0", "Gamma1", "0", "0", "0"],
            ["Gamma2", "-Gamma1", "0", "0", "0", "0"]]
    assert parse_matrix(rows, syms) == P.matrix  # same real symbols as definition.vector_symbols


def test_chaplygin_bracket_2604_6_matches_library():
    """Eq. (2604-6) typed from the paper: {L_i, L_j} = ε_ijk (L_k − D (L, γ) ρ_μ² J_i J_j γ_k),
    ρ_μ² = 1/det I_Q (eq. 2604-3), {L_i, γ_j} = ε_ijk γ_k. Equal to chaplygin_ball_bracket() as
    rational functions (numerator of the difference expands to 0)."""
    P = chaplygin_ball_bracket()
    syms = declare_symbols(["L1", "L2", "L3", "gamma1", "gamma2", "gamma3", "I1", "I2", "I3", "D"])
    rho2 = ("1/((I1 + D)*(I2 + D)*(I3 + D)*(1 - D*(gamma1**2/(I1 + D) + gamma2**2/(I2 + D)"
            " + gamma3**2/(I3 + D))))")
    Lg = "(L1*gamma1 + L2*gamma2 + L3*gamma3)"
    J = ["(I1 + D)", "(I2 + D)", "(I3 + D)"]

    def LL(i: int, j: int, k: int) -> str:
        return f"L{k + 1} - D*{Lg}*{rho2}*{J[i]}*{J[j]}*gamma{k + 1}"

    rows = [["0", LL(0, 1, 2), f"-({LL(0, 2, 1)})", "0", "gamma3", "-gamma2"],
            [f"-({LL(0, 1, 2)})", "0", LL(1, 2, 0), "-gamma3", "0", "gamma1"],
            [LL(0, 2, 1), f"-({LL(1, 2, 0)})", "0", "gamma2", "-gamma1", "0"],
            ["0", "gamma3", "-gamma2", "0", "0", "0"],
            ["-gamma3", "0", "gamma1", "0", "0", "0"],
            ["gamma2", "-gamma1", "0", "0", "0", "0"]]
    parsed = parse_matrix(rows, syms)
    library = {str(s): s for s in P.matrix.free_symbols}
    parsed = parsed.xreplace({syms[n]: library[n] for n in syms if n in library})  # assumptions differ
    for i in range(6):
        for j in range(6):
            assert sp.expand(sp.numer(sp.together(parsed[i, j] - P.matrix[i, j]))) == 0, (i, j)


# --- refusals, each with the position of the problem ----------------------------------------------

REFUSALS = [
    ("__import__('os').system('ls')", 0, "attribute access"),
    ("x.__class__", 0, "attribute access"),
    ("(lambda: 1)()", 1, "lambda"),
    ("open('f')", 0, "unknown function 'open'"),
    ("x if y else z", 0, "conditional"),
    ("[x for x in y]", 0, "comprehension"),
    ("'abc'", 0, "string"),
    ("x[0]", 0, "indexing"),
    ("x == y", 0, "comparison"),
    ("9**9**9", 3, "exponent 387420489 is too large"),
    ("10**100000", 4, "exponent 100000 is too large"),
    ("x^2", 1, "use ** for powers"),
    ("sin(x, y)", 7, "sin() takes 1 argument (2 given)"),
    ("atan2(x)", 0, "atan2() takes 2 arguments (1 given)"),
    ("sin(x=1)", 4, "keyword arguments"),
    ("sin(**x)", 4, "keyword arguments"),
    ("sin(*x)", 4, "starred"),
    ("foo(x)", 0, "unknown function 'foo'"),
    ("undeclared + 1", 0, "unknown name 'undeclared'; declared: E1, E2, I1"),
    ("1 + x.y", 4, "attribute access"),
    ("1 + (lambda: 1)()", 5, "lambda"),
    ("x(2)", 0, "declared variable, not a function"),
    ("pi(2)", 0, "constant, not a function"),
    ("sin + 1", 0, "is a function"),
    ("__class__", 0, "starting with '_'"),
    ("x @ y", 2, "operator '@'"),
    ("x // 2", 2, "operator '//'"),
    ("(x)  %  2", 5, "operator '%'"),
    ("not x", 0, "'not'"),
    ("~x", 0, "'~'"),
    ("x and y", 0, "boolean"),
    ("x < y < z", 0, "comparison"),
    ("x, y", 0, "tuple"),
    ("{x: 1}", 0, "dict"),
    ("(x := 1)", 1, "assignment"),
    ("f'{x}'", 0, "f-string"),
    ("(yield x)", 1, "yield"),
    ("True", 0, "True is not allowed"),
    ("None", 0, "None is not allowed"),
    ("2j*x", 0, "complex"),
    ("b'x'", 0, "string"),
    ("1e16*x", 0, "too large"),
    ("x + 10000000000000001", 4, "too large"),
    ("1e-151*x", 0, "decimal places"),
    ("x**65", 3, "exponent 65 is too large"),
    ("x**0.333", 3, "denominator above 64"),
    ("1/0", 2, "division by zero"),
    ("x/(y - y)", 3, "division by zero"),
    ("0**-1", 0, "division by zero"),
    ("x + θ", 4, "non-ASCII"),
    ("x\x00", 1, "control character"),
    ("x # note\n + y", 2, "comments"),
    ("", 0, "empty"),
    ("   ", 0, "empty"),
    ("sin(x", 3, "never closed"),
    ("x y", 2, "invalid syntax"),
    ("x = 1", 2, "invalid syntax"),
]


@pytest.mark.parametrize("text, position, reason", REFUSALS)
def test_refusals_with_position(text, position, reason):
    err = refuse(text)
    assert err.position == position, (err.position, str(err))
    assert reason in err.reason
    assert err.text == text
    assert str(err) == f"{err.reason} at character {position}"


def test_unknown_name_hints():
    assert "did you mean 'thetadot'?" in refuse("thetadt*2").reason
    assert "did you mean log?" in refuse("ln(x)").reason
    with pytest.raises(ExpressionError) as info:
        parse_expression("e + 1", declare_symbols(["x"]))  # e undeclared: a hint towards E
    assert "Euler's number is E" in info.value.reason and info.value.position == 0


def test_size_limits():
    err = refuse("x" * 5000)
    assert (err.position, "5000 characters" in err.reason) == (2000, True)
    deep = "(" * 200 + "x" + ")" * 200                      # 200-deep parentheses
    assert refuse(deep).position == 60                       # the 61st bracket
    deep_sum = "(x+" * 200 + "x" + ")" * 200
    assert refuse(deep_sum, max_length=5000).position == 180
    unary = "-" * 100 + "x"                                  # deep without brackets: the AST depth
    err = refuse(unary)
    assert err.position == 60 and "nested deeper than 60" in err.reason
    assert parse("-" * 59 + "x") == -x                       # 60 levels (59 signs and x) are fine
    # a long sum is one level: 900 terms parse although max_depth is 60
    assert parse("+".join(["x"] * 900)) == 900 * x
    err = refuse("+".join(["x"] * 11), max_nodes=10)        # 21 nodes; text[:11] holds 11
    assert "21 nodes" in err.reason and err.position == 10
    with pytest.raises(ValueError):
        parse("x", max_depth=0)


def test_literal_exponents_refused_before_sympy(monkeypatch):
    """9**9**9 and 10**100000 never reach sympy: the build pass is not entered at all."""
    def boom(*args, **kwargs):
        raise AssertionError("sympy build reached")
    monkeypatch.setattr(ex._Parser, "build", boom)
    for text, position in [("9**9**9", 3), ("10**100000", 4), ("x + 2**2**2**2**2", 7), ("(2**64)**8", 0)]:
        assert refuse(text).position == position
    with pytest.raises(AssertionError):
        parse("2**2**2")  # 2**4: valid, so the (patched) build is reached


@pytest.mark.parametrize("text, position, reason", [
    # sympy's automatic evaluation asks evalf about constants: each of these hangs or runs out of
    # memory inside sympy (checked by hand: > 10 s / MemoryError) unless refused first
    ("abs(tan(exp(10**15)))", 8, "exceeds"),
    ("exp(exp(1000000000000000)) - 1", 4, "exceeds"),
    ("abs(tan(exp(x - x + 10**15)))", 8, "exceeds"),       # a constant born from cancellation
    ("sign(sin(exp(1e15)))", 9, "exceeds"),
    ("exp(1000000000000000*log(2))", 0, "exp(c*log(...))"),  # sympy rewrites as 2**(10**15)
    ("E**(100*log(x))", 0, "exp(c*log(...))"),
    ("(2**64)**sqrt(4096)", 0, "bits"),                    # exponent 64 appears only inside sympy
    ("2**sqrt(4096)**2", 3, "exponent 4096"),
    ("((((x**64)**64)**64)**64)", 2, "exponent 262144"),   # nested powers combine
    ("*".join(["1e15"] * 40), 0, "bits"),
    ("sqrt(-1)", 0, "not certainly real"),
    ("log(0)", 0, "log"),
    ("acos(2)", 0, "not real"),
    ("tan(pi/2)", 0, "infinite"),
    ("1/(cos(1)**2 + sin(1)**2 - 1)", 3, "denominator may be zero"),  # exactly 0, not provably
    ("atan2(0, 0)", 0, "undefined"),
])
def test_resource_and_domain_guards(text, position, reason):
    err = refuse(text)
    assert (err.position, reason in err.reason) == (position, True), str(err)


def test_worst_case_inputs_are_accepted_and_end():
    """Largest accepted inputs (2000 characters) whose constants sympy evaluates numerically: each is
    parsed, within a wide hang guard (how fast is bench/'s)."""
    cases = [
        fill(f"sign(sin({k})**2 + cos({k})**2 - 1)" for k in range(1, 99)),  # evalf of exact zeros
        fill(f"cos(pi/{k})" for k in range(2, 400)),
        fill(f"asin(sin({k}/7))" for k in range(2, 400)),
        "sin(" * 59 + "1" + ")" * 59,
        "+".join(["x"] * 999),
    ]
    for text in cases:
        assert len(text) <= 2000
        with hang_guard(WORST_S, f"parsing {text[:40]!r}"):
            parse(text)


def fill(terms, limit: int = 2000) -> str:
    """Join terms with '+' up to ``limit`` characters."""
    out = ""
    for term in terms:
        if len(out) + len(term) + 1 > limit:
            break
        out = f"{out}+{term}" if out else term
    return out


# --- declared names --------------------------------------------------------------------------------

def test_declare_symbols():
    syms = declare_symbols(["M1", "Gamma1", "e", "E1", "I"])
    assert list(syms) == ["M1", "Gamma1", "e", "E1", "I"]
    assert syms["M1"] == sp.Symbol("M1", real=True)
    assert parse_expression("I*M1", syms) == sp.Symbol("I", real=True) * syms["M1"]  # not sympy's I


@pytest.mark.parametrize("names, fragment", [
    (["θ"], "'θ' is not ASCII"),
    (["ℌ"], "not ASCII"),
    (["x y"], "not an identifier"),
    (["1x"], "not an identifier"),
    (["x-y"], "not an identifier"),
    ([""], "empty"),
    (["_x"], "starts with '_'"),
    (["__class__"], "starts with '_'"),
    (["a" * 33], "longer than 32"),
    (["sin"], "collides with the function sin()"),
    (["E"], "collides with the constant E"),
    (["pi"], "collides with the constant pi"),
    (["lambda"], "keyword"),
    (["None"], "keyword"),
    (["x", "x"], "'x' is declared twice"),
    ([3], "must be strings"),
    ("xyz", "not a single string"),
])
def test_declare_symbols_refusals(names, fragment):
    with pytest.raises(ExpressionError) as info:
        declare_symbols(names)
    assert info.value.position is None and fragment in info.value.reason


def test_symbol_mapping_is_checked_too():
    with pytest.raises(ExpressionError, match="constant E"):
        parse_expression("E", {"E": sp.Symbol("E")})
    with pytest.raises(TypeError):
        parse_expression("x", {"x": "x"})


def test_allowed_functions_cannot_be_widened(monkeypatch):
    monkeypatch.setitem(ALLOWED_FUNCTIONS, "open", sp.sin)
    assert "unknown function 'open'" in refuse("open(x)").reason


# --- matrices ---------------------------------------------------------------------------------------

def test_parse_matrix_errors_carry_the_entry():
    with pytest.raises(ExpressionError) as info:
        parse_matrix([["0", "x*y - z"], ["-(x*y - z)", "0 + q"]], S)
    err = info.value
    assert (err.entry, err.position, err.text) == ((1, 1), 4, "0 + q")
    assert str(err) == f"{err.reason} at character 4 of matrix entry (1, 1)"
    with pytest.raises(ExpressionError) as info:
        parse_matrix([["x", "y"], ["z"]], S)
    assert (info.value.entry, info.value.position) == (None, None) and "row 1" in info.value.reason
    with pytest.raises(ExpressionError, match="limit is 4"):
        parse_matrix([["x"] * 3] * 2, S, max_entries=4)
    with pytest.raises(ExpressionError, match="limit is 3"):
        parse_matrix([["x", "xxxx"]], S, max_length=3)
    with pytest.raises(ExpressionError) as info:
        parse_matrix([["x", 1]], S)
    assert info.value.entry == (0, 1)
    assert parse_matrix([["x", "2.5"]], S) == sp.Matrix([[x, sp.Rational(5, 2)]])


def test_error_is_picklable_value_error():
    err = ExpressionError("unknown name 'q'", 4, "0 + q", (1, 1))
    back = pickle.loads(pickle.dumps(err))
    assert isinstance(back, ValueError)
    assert (back.reason, back.position, back.text, back.entry, str(back)) == \
        (err.reason, err.position, err.text, err.entry, str(err))
    assert err.as_dict()["entry"] == [1, 1]


# --- no eval ----------------------------------------------------------------------------------------

def test_module_uses_no_eval():
    """Identifiers in the module's code (comments and strings stripped): no eval/exec/compile/
    sympify/parse_expr/S()/__import__, and ``parse`` only as ``ast.parse``."""
    source = "\n".join(path.read_text() for path in sorted(Path(ex.__file__).parent.glob("*.py")))  # the package
    tokens = [t for t in tokenize.generate_tokens(io.StringIO(source).readline)
              if t.type not in (tokenize.COMMENT, tokenize.STRING)]
    names = [t.string for t in tokens if t.type == tokenize.NAME]
    forbidden = {"eval", "exec", "compile", "sympify", "parse_expr", "S", "__import__", "literal_eval",
                 "lambdify", "parsing", "import_module", "globals", "locals", "vars"}
    assert not forbidden & set(names)
    parses = [i for i, t in enumerate(tokens) if t.string == "parse"]
    assert parses and all(tokens[i - 1].string == "." and tokens[i - 2].string == "ast" for i in parses)
    assert "import sympy as sp" in source and "from sympy.parsing" not in source


# --- fuzzing ----------------------------------------------------------------------------------------

TOKENS = ["x", "y", "1", "2.5", "1e15", "+", "-", "*", "/", "**", "^", "(", ")", "sin(", "atan2(", ",",
          "[", "]", ".", "e", "E", "pi", " ", "lambda", ":", "'", "_", "=", "exp(", "log(", "abs(", "9", "0"]


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.sampled_from(TOKENS), max_size=25).map("".join) | st.text(max_size=30))
def test_fuzz_only_expression_errors(text):
    """Any text: a sympy Expr or an ExpressionError with a position inside the text (within a hang guard)."""
    with hang_guard(FAST_S, f"parsing {text!r}"):
        try:
            assert isinstance(parse(text), sp.Expr)
        except ExpressionError as err:
            assert err.position is None or 0 <= err.position <= len(text)


def _expressions():
    """Random fully parenthesised expressions with their float value at x = 0.7, y = -1.3 and the
    largest intermediate magnitude (an oracle computed alongside the text, no eval)."""
    point = {"x": 0.7, "y": -1.3}
    leaves = (st.sampled_from(["x", "y"]).map(lambda n: (n, point[n], 1.3))
              | st.integers(-9, 9).map(lambda k: (str(k), float(k), abs(k)))
              | st.sampled_from(["0.5", "2.25", "1e-2", "3.75"]).map(lambda s: (s, float(s), float(s))))

    def node(text, value, *children):
        return text, value, max([abs(value) if math.isfinite(value) else math.inf] + [c[2] for c in children])

    def extend(children):
        binary = st.tuples(children, st.sampled_from("+-*/"), children).map(
            lambda t: node(f"({t[0][0]}){t[1]}({t[2][0]})", _binary(t[1], t[0][1], t[2][1]), t[0], t[2]))
        power = st.tuples(children, st.integers(0, 3)).map(
            lambda t: node(f"({t[0][0]})**{t[1]}", t[0][1] ** t[1], t[0]))
        funcs = st.tuples(st.sampled_from(["sin", "cos", "atan", "tanh"]), children).map(
            lambda t: node(f"{t[0]}({t[1][0]})", getattr(math, t[0])(t[1][1]) if math.isfinite(t[1][1])
                           else math.nan, t[1]))
        return binary | power | funcs
    return st.recursive(leaves, extend, max_leaves=12)


def _binary(op: str, a: float, b: float) -> float:
    """The float oracle; a (nearly) vanishing denominator gives nan (the case is skipped)."""
    if op == "/":
        return a / b if abs(b) > 1e-6 else math.nan
    return {"+": a + b, "-": a - b, "*": a * b}[op]


@settings(max_examples=150, deadline=None)
@given(_expressions())
def test_fuzz_values_match_float_oracle(case):
    """Parsed value (sympy, 30 digits) = float value of the same text, within float round-off of the
    largest intermediate (1e-12 * (1 + scale)); 150 random expressions with up to 12 leaves."""
    text, value, scale = case
    assume(math.isfinite(value) and scale < 1e12)
    try:
        expr = parse(text)
    except ExpressionError as err:  # only a constant denominator that is (nearly) zero may be refused
        assert "denominator" in err.reason or "division by zero" in err.reason, str(err)
        return
    got = complex(expr.evalf(30, subs={x: sp.Rational(7, 10), y: sp.Rational(-13, 10)}))
    assert abs(got - value) <= 1e-12 * (1 + scale), (text, got, value, scale)
