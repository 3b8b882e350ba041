"""The resource limits of the safe parser (see :mod:`nonholonomic.expressions`).

All are deterministic measures of the input (lengths, counts, exponents, bits, certified magnitudes): the
same text is accepted or refused, with the same words, on every machine and at any load. No clock
decides a refusal."""

from __future__ import annotations

#: Longest accepted variable name.
MAX_NAME_LENGTH = 32
#: Largest accepted numeric literal (absolute value).
MAX_LITERAL = 10**15
#: Most digits after the decimal point of a literal (``1e-150`` is accepted, ``1e-151`` not).
MAX_DECIMAL_PLACES = 150
#: Bound on |numeric exponent| and on its denominator.
MAX_EXPONENT = 64
#: Bound on |exponent| and its denominator of powers sympy forms by combining nested powers.
MAX_RESULT_EXPONENT = 4096
#: Bits of numerator / denominator of any exact number produced while parsing.
MAX_NUMBER_BITS = 512
#: Bound on |value| of any constant sub-expression (certified by interval arithmetic).
MAX_CONSTANT_MAGNITUDE = 1e150
#: Entries of a matrix accepted by :func:`parse_matrix` (override with ``max_entries=``).
MAX_MATRIX_ENTRIES = 400
