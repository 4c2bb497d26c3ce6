"""CasADi expressions compiled to vectorised numpy functions.

The fits evaluate a primitive's signed distance and its parameter Jacobian on thousands of
points many times per reconstruction.  The formulas are written once
(:mod:`wholearm_tools.fit.models`), differentiated by CasADi, and the resulting SX algorithm is
translated, instruction by instruction, into the body of a Python function: instructions that
depend on a *point* input become numpy operations on whole columns, those that depend only on
the parameters become Python scalar arithmetic (done once per call, not once per point).  A
CasADi ``Function.map`` over the points costs about 10 microseconds per point on this machine;
the translated code costs about as much as hand-written numpy.

Only the elementwise operations the models use are supported; anything else raises
:class:`UntranslatableOperationError` at generation time (never at run time).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection
from typing import Any

import casadi as ca
import numpy as np


class UntranslatableOperationError(NotImplementedError):
    """A CasADi operation the translation has no numpy form for: raised while a function is
    generated, never while it is evaluated."""


_UNARY = {
    ca.OP_SQRT: ("np.sqrt", "math.sqrt"), ca.OP_SIN: ("np.sin", "math.sin"),
    ca.OP_COS: ("np.cos", "math.cos"), ca.OP_TAN: ("np.tan", "math.tan"),
    ca.OP_FABS: ("np.abs", "abs"), ca.OP_EXP: ("np.exp", "math.exp"),
    ca.OP_LOG: ("np.log", "math.log"), ca.OP_LOG1P: ("np.log1p", "math.log1p"),
    ca.OP_ACOS: ("np.arccos", "math.acos"), ca.OP_ASIN: ("np.arcsin", "math.asin"),
    ca.OP_ATAN: ("np.arctan", "math.atan"),
}
_BINARY_FN = {
    ca.OP_FMAX: ("np.maximum", "max"), ca.OP_FMIN: ("np.minimum", "min"),
    ca.OP_ATAN2: ("np.arctan2", "math.atan2"),
}
_INFIX = {
    ca.OP_ADD: "+", ca.OP_SUB: "-", ca.OP_MUL: "*", ca.OP_DIV: "/", ca.OP_LT: "<",
    ca.OP_LE: "<=", ca.OP_EQ: "==", ca.OP_NE: "!=", ca.OP_POW: "**", ca.OP_CONSTPOW: "**",
}


def numpy_function(f: ca.Function, point_inputs: Collection[int],
                   name: str = "generated") -> Callable[..., tuple[tuple[Any, ...], ...]]:
    """A Python function computing ``f`` (an SX function) on columns of points.

    Parameters
    ----------
    f : casadi.Function
        An SX function of dense vector inputs.
    point_inputs : indices of the inputs given as ``(size, N)`` arrays (one column per point);
        the other inputs are 1-D parameter vectors.
    name : name of the generated function (shows in tracebacks and profiles).

    Returns
    -------
    callable ``g(*inputs)`` returning, per output of ``f``, a tuple of its structural non-zeros
    (column-major, as CasADi stores them); each is a float (when it does not depend on a point
    input) or an ``(N,)`` array.
    """
    if not f.is_a("SXFunction"):
        raise TypeError(f"{f.name()} is not an SX function")
    lines = [f"def {name}({', '.join(f'i{k}' for k in range(f.n_in()))}):"]
    lines += [f"    i{k} = i{k}.tolist()" for k in range(f.n_in()) if k not in point_inputs]
    vector: dict[int, bool] = {}
    outputs: dict[int, dict[int, str]] = {}
    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        out = f.instruction_output(k)
        arg = f.instruction_input(k)
        if op == ca.OP_INPUT:
            vector[out[0]] = arg[0] in point_inputs
            lines.append(f"    w{out[0]} = i{arg[0]}[{arg[1]}]")
            continue
        if op == ca.OP_OUTPUT:
            # the work slot is reused by later instructions: copy the value out now
            var = f"o{out[0]}_{out[1]}"
            outputs.setdefault(out[0], {})[out[1]] = var
            lines.append(f"    {var} = w{arg[0]}")
            continue
        if op == ca.OP_CONST:
            vector[out[0]] = False
            lines.append(f"    w{out[0]} = {float(f.instruction_constant(k))!r}")
            continue
        lines.append(f"    w{out[0]} = {_expression(op, arg, vector)}")
        n_args = 2 if op in _INFIX or op in _BINARY_FN or op == ca.OP_IF_ELSE_ZERO else 1
        vector[out[0]] = any(vector.get(a, False) for a in arg[:n_args])
    returns = []
    for j in range(f.n_out()):
        nnz = f.sparsity_out(j).nnz()
        returns.append("(" + "".join(f"{outputs.get(j, {}).get(i, '0.0')}, "
                                     for i in range(nnz)) + ")")
    lines.append(f"    return ({''.join(r + ', ' for r in returns)})")
    namespace: dict[str, Any] = {"np": np, "math": math}
    exec(compile("\n".join(lines), f"<{name}>", "exec"), namespace)
    return namespace[name]


def _expression(op: int, arg: list[int], vector: dict[int, bool]) -> str:
    a = [f"w{x}" for x in arg]
    vec = any(vector.get(x, False) for x in arg[:2])
    if op in _INFIX:
        return f"({a[0]} {_INFIX[op]} {a[1]})"
    if op == ca.OP_NEG:
        return f"(-{a[0]})"
    if op == ca.OP_SQ:
        return f"({a[0]} * {a[0]})"
    if op == ca.OP_TWICE:
        return f"(2.0 * {a[0]})"
    if op == ca.OP_INV:
        return f"(1.0 / {a[0]})"
    if op == ca.OP_NOT:
        return f"np.logical_not({a[0]})" if vector.get(arg[0], False) else f"(not {a[0]})"
    if op == ca.OP_IF_ELSE_ZERO:
        return f"np.where({a[0]}, {a[1]}, 0.0)" if vec else f"({a[1]} if {a[0]} else 0.0)"
    if op in _UNARY:
        return f"{_UNARY[op][0 if vector.get(arg[0], False) else 1]}({a[0]})"
    if op in _BINARY_FN:
        return f"{_BINARY_FN[op][0 if vec else 1]}({a[0]}, {a[1]})"
    raise UntranslatableOperationError(f"CasADi operation {op} has no numpy translation")
