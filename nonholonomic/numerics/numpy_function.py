"""Sympy expressions compiled to numpy functions that pickle as their source (so they can be remembered,
:mod:`nonholonomic.memo`).

``sympy.lambdify`` writes a Python function (after common subexpression elimination, the slow part)
and compiles it in a namespace of numpy's names. Its result does not pickle; a :class:`NumpyFunction`
keeps the generated source and compiles it again, in the same namespace, when it is unpickled.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from functools import lru_cache
from typing import Any

import sympy as sp

#: The name lambdify gives the function it generates.
GENERATED_NAME = "_lambdifygenerated"


@lru_cache(maxsize=1)
def _numpy_namespace() -> dict[str, Any]:
    """The names lambdify's numpy printer compiles its source with (numpy's functions and constants)."""
    return dict(sp.lambdify([], 0, modules="numpy").__globals__)


def _compiled(source: str) -> Callable[..., Any]:
    namespace = dict(_numpy_namespace())
    exec(compile(source, f"<{GENERATED_NAME}>", "exec"), namespace)  # noqa: S102 - source lambdify wrote
    return namespace[GENERATED_NAME]


class NumpyFunction:
    """``f(*args)`` of a lambdified expression list; pickles as its generated ``source``."""

    __slots__ = ("source", "_fn")

    def __init__(self, source: str) -> None:
        self.source = source
        self._fn = _compiled(source)

    def __call__(self, *args: Any) -> Any:
        return self._fn(*args)

    def __reduce__(self) -> tuple[type, tuple[str]]:
        return NumpyFunction, (self.source,)


def lambdify_numpy(args: Sequence[sp.Symbol], exprs: Sequence[sp.Expr]) -> Callable[..., Any]:
    """``sympy.lambdify(args, exprs, "numpy", cse=True)``, as a :class:`NumpyFunction` when its namespace
    is numpy's alone (else the plain function, which is then not remembered)."""
    fn = sp.lambdify(list(args), list(exprs), modules="numpy", cse=True)
    standard = _numpy_namespace()
    if any(standard.get(name, _MISSING) is not value for name, value in fn.__globals__.items()):
        return fn  # the printer added a name of its own (rare): keep the function as it is
    return NumpyFunction(inspect.getsource(fn))


_MISSING = object()
