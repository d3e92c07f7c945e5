"""A canonical operand order for forms with Constants, so that a form's signature (the
key of FFCx's JIT cache) is the same in every run of a process and every process.

UFL sorts the operands of a sum or product when it builds them (``ufl.sorting.cmp_expr``).
It compares two Coefficients by their creation counts, but two Constants by ``repr``,
which ends in the Constant's process-wide creation count written in decimal: the string
order of two counts flips when they straddle a power of ten ('9' > '17', '109' < '117').
A scene that creates its Constants in the same order in every run therefore built
``a·b`` in one run and ``b·a`` in the next as the counts grew, and FFCx compiled the
form again (measured on the coarse eye: 10 of its 66 forms and expressions had new
signatures in a process's second run and none in its third; with :func:`install`, none in
either). Comparing Constants by their count as a number, as UFL compares Coefficients,
makes the order depend on the Constants' relative creation order only, which a scene
fixes (tests/test_compile_once.py runs two cases with new values in one process).
"""

from __future__ import annotations

import ufl.sorting
from ufl.constant import Constant


def _cmp_constant(a: Constant, b: Constant) -> int:
    """Order two Constants as UFL orders two Coefficients: by creation count."""
    return (a.count() > b.count()) - (a.count() < b.count())


def install() -> None:
    """Make UFL order Constants by count (idempotent; a comparison UFL already registers
    for Constants is kept). Effective for expressions built after it: this module calls
    it when imported, and ``eyemech.forms`` and the run contract import it first."""
    ufl.sorting._terminal_cmps.setdefault(Constant._ufl_typecode_, _cmp_constant)


install()
