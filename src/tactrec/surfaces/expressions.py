"""Safe parsing of the math expressions in model files.

Expressions are parsed with :func:`ast.parse` (which only parses) and the tree
is translated node by node into sympy.  Nothing read from a file is ever
evaluated as Python: only numbers, the declared symbols and a fixed list of
functions are accepted.
"""

from __future__ import annotations

import ast
import functools
from typing import Mapping

__all__ = ["parse_expression", "functions", "constants"]


@functools.cache
def functions() -> dict:
    """The functions an expression may call, by name (sympy, imported when first needed)."""
    import sympy as sp

    return {"sin": sp.sin, "cos": sp.cos, "tan": sp.tan,
            "asin": sp.asin, "acos": sp.acos, "atan": sp.atan, "atan2": sp.atan2,
            "sinh": sp.sinh, "cosh": sp.cosh, "tanh": sp.tanh,
            "exp": sp.exp, "log": sp.log, "sqrt": sp.sqrt, "abs": sp.Abs}


@functools.cache
def constants() -> dict:
    """The named constants of an expression."""
    import sympy as sp

    return {"pi": sp.pi, "e": sp.E}

_BINARY = {
    ast.Add: lambda a, b: a + b,
    ast.Sub: lambda a, b: a - b,
    ast.Mult: lambda a, b: a * b,
    ast.Div: lambda a, b: a / b,
    ast.Pow: lambda a, b: a**b,
}


def parse_expression(text: str, symbols: Mapping[str, sp.Expr]) -> sp.Expr:
    """Translate the expression ``text`` into a sympy expression.

    Parameters
    ----------
    text : str or number
        The expression, e.g. ``"(R + r*cos(v))*cos(u)"``.
    symbols : mapping of str to sympy expression
        The names allowed in the expression (variables and parameters).

    Raises
    ------
    ValueError
        With a one-line message saying what is not allowed.
    """
    import sympy as sp

    if isinstance(text, bool):
        raise ValueError(f"expected an expression, got {text!r}")
    if isinstance(text, (int, float)):
        return sp.nsimplify(text) if isinstance(text, int) else sp.Float(text)
    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"expected an expression, got {text!r}")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise ValueError(f"cannot parse expression {text!r}: {exc.msg}") from None
    return _translate(tree.body, symbols, text)


def _translate(node: ast.AST, symbols: Mapping[str, sp.Expr], text: str) -> sp.Expr:
    import sympy as sp

    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise ValueError(f"unexpected constant {node.value!r} in {text!r}")
        return sp.Integer(node.value) if isinstance(node.value, int) else sp.Float(node.value)
    if isinstance(node, ast.Name):
        if node.id in symbols:
            return symbols[node.id]
        if node.id in constants():
            return constants()[node.id]
        raise ValueError(f"unknown name {node.id!r} in {text!r}")
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.BitXor):
        raise ValueError(f"'^' is not a power here; write x**2 in {text!r}")
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        left = _translate(node.left, symbols, text)
        right = _translate(node.right, symbols, text)
        return _BINARY[type(node.op)](left, right)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        operand = _translate(node.operand, symbols, text)
        return -operand if isinstance(node.op, ast.USub) else operand
    if isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name):
            raise ValueError(f"calling {ast.unparse(node.func)!r} is not allowed in {text!r}")
        if node.func.id not in functions():
            raise ValueError(f"unknown function {node.func.id!r} in {text!r}")
        if node.keywords:
            raise ValueError(f"keyword arguments are not allowed in {text!r}")
        args = [_translate(arg, symbols, text) for arg in node.args]
        return functions()[node.func.id](*args)
    raise ValueError(f"{type(node).__name__} syntax is not allowed in {text!r}")
