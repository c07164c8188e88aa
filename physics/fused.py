"""The fused kernel, generated from :func:`physics.kernel.point_outputs` by tracing it.

:func:`plan` runs :func:`physics.kernel.point_outputs` once on traced values, which record every
operation the equation functions perform, in their order. The record is cut at the expensive
elementary functions (tan, cbrt, log, exp): numpy runs each of those over a block of points with
its vectorized (SIMD) loops, and the arithmetic between them (square roots included) becomes
Python source of one loop per stage, which :mod:`physics.compiled` compiles with numba. Every
intermediate of a stage stays in registers; only what a later stage reads goes through a block
buffer that stays in the CPU's cache. The operations and their order are those of the numpy
kernel, IEEE arithmetic rounds them alike, and the elementary functions are numpy's own, so the
fused kernel gives the numpy kernel's bits (tested to 1e-12). No equation is written here: the
stages are generated from the functions that the numpy and single-point paths run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import kernel

__all__ = ["INPUTS", "VECTORIZED", "Plan", "plan"]

#: How many input columns the stages read: the point's inputs, then the material factors.
INPUTS = len(kernel.POINT_INPUTS) + len(kernel.MATERIAL_FACTORS)

#: The elementary functions numpy runs over a block (its SIMD loops); the rest is compiled arithmetic.
VECTORIZED = {"tan": np.tan, "cbrt": np.cbrt, "log": np.log, "exp": np.exp}

_INFIX = {"add": "+", "sub": "-", "mul": "*", "truediv": "/", "ge": ">="}


class _Graph:
    """The operations of a trace, in order: (op, arguments), each argument a node's index; the
    arguments of an ``input`` node are its position, those of a ``const`` node its value."""

    def __init__(self):
        self.nodes: list[tuple[str, tuple]] = []

    def _node(self, op: str, args: tuple) -> _Traced:
        self.nodes.append((op, args))
        return _Traced(self, len(self.nodes) - 1)

    def input(self, position: int) -> _Traced:
        return self._node("input", (position,))

    def const(self, value: float) -> _Traced:
        return self._node("const", (value,))

    def add(self, op: str, *args) -> _Traced:
        return self._node(op, tuple(a.index if isinstance(a, _Traced) else self.const(a).index for a in args))


class _Traced:
    """A value of the trace: arithmetic and numpy's one-argument ufuncs on it add nodes."""

    __slots__ = ("graph", "index")

    def __init__(self, graph: _Graph, index: int):
        self.graph, self.index = graph, index

    def _binary(self, op: str, other, swapped: bool = False) -> _Traced:
        if not isinstance(other, (_Traced, int, float)):
            return NotImplemented
        return self.graph.add(op, *((other, self) if swapped else (self, other)))

    def __add__(self, other):
        return self._binary("add", other)

    def __radd__(self, other):
        return self._binary("add", other, True)

    def __sub__(self, other):
        return self._binary("sub", other)

    def __rsub__(self, other):
        return self._binary("sub", other, True)

    def __mul__(self, other):
        return self._binary("mul", other)

    def __rmul__(self, other):
        return self._binary("mul", other, True)

    def __truediv__(self, other):
        return self._binary("truediv", other)

    def __rtruediv__(self, other):
        return self._binary("truediv", other, True)

    def __ge__(self, other):
        return self._binary("ge", other)

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        if method != "__call__" or kwargs or len(inputs) != 1 or ufunc.__name__ not in {*VECTORIZED, "sqrt"}:
            return NotImplemented
        return self.graph.add(ufunc.__name__, inputs[0])


@dataclass(frozen=True)
class Plan:
    """The stages of the fused kernel for one choice of ``extras``.

    Attributes
    ----------
    source : str
        Python source of the functions ``stage_0`` ... ``stage_<levels - 1>``, each
        ``(inputs, buffers, out, rows, start, n)``: a loop over points ``start:start + n`` (``j``
        in the block, ``i`` in the call) of compiled arithmetic. [-]
    levels : int
        Number of compiled stages. [1]
    vectorized : tuple
        For each level 1 ... levels - 1, the numpy calls run before that level's stage:
        (ufunc name, argument, buffer row), the argument ``("input", k)`` or ``("buffer", row)``. [-]
    buffers : int
        Rows of the block buffer. [1]
    """

    source: str
    levels: int
    vectorized: tuple
    buffers: int


def plan(extras: bool) -> Plan:
    """Trace :func:`physics.kernel.point_outputs` and cut it into stages.

    Parameters
    ----------
    extras : bool
        As in :func:`physics.kernel.point_outputs`.

    Returns
    -------
    Plan
        The stages; their loops read ``inputs[k][i]`` (``k`` in the order of
        :data:`physics.kernel.POINT_INPUTS` then :func:`physics.kernel.material`'s factors) and
        write output ``m`` of :data:`physics.OUTPUTS` to ``out[rows[m], i]`` where ``rows[m] >= 0``.
    """
    graph = _Graph()
    inputs = [graph.input(k) for k in range(INPUTS)]
    point, material = inputs[:len(kernel.POINT_INPUTS)], inputs[len(kernel.POINT_INPUTS):]
    results = kernel.point_outputs(tuple(point), tuple(material), extras)
    outputs = [r.index if isinstance(r, _Traced) else graph.const(r).index for r in results]
    nodes = graph.nodes
    level = []
    for op, args in nodes:
        below = max((level[a] for a in args), default=0) if op not in ("input", "const") else 0
        level.append(below + 1 if op in VECTORIZED else below)
    # What numpy computes, and a node read by numpy or in another stage than its own, goes
    # through a buffer row; the rest stays in registers.
    buffered = {index for index, (op, _) in enumerate(nodes) if op in VECTORIZED}
    for index, (op, args) in enumerate(nodes):
        if op not in ("input", "const"):
            buffered.update(a for a in args if nodes[a][0] not in ("input", "const")
                            and (op in VECTORIZED or level[a] != level[index]))
    rows = {index: row for row, index in enumerate(sorted(buffered))}
    levels = max(level) + 1
    vectorized = tuple(tuple((op, _argument(nodes, rows, args[0]), rows[index])
                             for index, (op, args) in enumerate(nodes)
                             if op in VECTORIZED and level[index] == stage)
                       for stage in range(1, levels))
    source = "\n\n".join(_stage_source(nodes, level, rows, outputs, stage) for stage in range(levels))
    return Plan(source, levels, vectorized, len(rows))


def _argument(nodes: list, rows: dict[int, int], index: int) -> tuple[str, int]:
    return ("input", nodes[index][1][0]) if nodes[index][0] == "input" else ("buffer", rows[index])


def _stage_source(nodes: list, level: list[int], rows: dict[int, int], outputs: list[int], stage: int) -> str:
    """The loop of one compiled stage: its nodes in trace order, then the outputs of its level.

    Columns, buffer rows and output rows are bound before the loop, so that the loop body is
    arithmetic on locals, loads and stores.
    """
    lines, known, bound = [], set(), {}

    def column(name: str, expression: str) -> str:
        bound.setdefault(name, expression)
        return name

    def value(index: int) -> str:
        op, args = nodes[index]
        if op == "const":
            return _literal(args[0])
        if index not in known:  # an input or an earlier stage's buffered node: read once per point
            known.add(index)
            read = (f"{column(f'c{args[0]}', f'inputs[{args[0]}]')}[i]" if op == "input"
                    else f"{column(f'b{rows[index]}', f'buffers[{rows[index]}]')}[j]")
            lines.append(f"v{index} = {read}")
        return f"v{index}"

    for index, (op, args) in enumerate(nodes):
        if level[index] != stage or op in ("input", "const") or op in VECTORIZED:
            continue
        operands = [value(a) for a in args]
        expression = f"np.sqrt({operands[0]})" if op == "sqrt" else f" {_INFIX[op]} ".join(operands)
        lines.append(f"v{index} = {expression}")
        known.add(index)
        if index in rows:
            lines.append(f"{column(f'b{rows[index]}', f'buffers[{rows[index]}]')}[j] = v{index}")
    for position, index in enumerate(outputs):
        if level[index] == stage:
            row = column(f"r{position}", f"rows[{position}]")
            lines.append(f"if {row} >= 0:")
            lines.append(f"    out[{row}, i] = {value(index)}")
    body = "\n".join("        " + line for line in lines) or "        pass"
    binds = "".join(f"    {name} = {expression}\n" for name, expression in bound.items())
    return (f"def stage_{stage}(inputs, buffers, out, rows, start, n):\n{binds}"
            f"    for j in range(n):\n        i = start + j\n{body}\n")


def _literal(value) -> str:
    if isinstance(value, bool):
        return "1.0" if value else "0.0"
    value = float(value)
    if math.isinf(value):
        return "np.inf" if value > 0 else "-np.inf"
    return repr(value)
