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

import heapq
import math
from dataclasses import dataclass

import numpy as np

from . import kernel

__all__ = ["INPUTS", "VECTORIZED", "Plan", "Trace", "plan", "trace"]

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
class Trace:
    """The operations :func:`physics.kernel.point_outputs` performs, in its order.

    Attributes
    ----------
    nodes : tuple
        (op, arguments) of each operation. Nodes ``0 ... INPUTS - 1`` are the ``input`` nodes of
        :data:`physics.kernel.POINT_INPUTS` then :func:`physics.kernel.material`'s factors (their
        arguments: their position); a ``const`` node's argument is its value; any other op (``add``,
        ``sub``, ``mul``, ``truediv``, ``ge``, ``sqrt`` and the keys of :data:`VECTORIZED`) takes
        the indices of its operands' nodes. [-]
    outputs : tuple
        For each output of :data:`physics.OUTPUTS`, the index of its node. [-]
    """

    nodes: tuple
    outputs: tuple


def trace(extras: bool) -> Trace:
    """Run :func:`physics.kernel.point_outputs` once on traced values (``extras`` as there)."""
    graph = _Graph()
    inputs = [graph.input(k) for k in range(INPUTS)]
    point, material = inputs[:len(kernel.POINT_INPUTS)], inputs[len(kernel.POINT_INPUTS):]
    results = kernel.point_outputs(tuple(point), tuple(material), extras)
    outputs = tuple(r.index if isinstance(r, _Traced) else graph.const(r).index for r in results)
    return Trace(tuple(graph.nodes), outputs)


@dataclass(frozen=True)
class Plan:
    """The stages of the fused kernel for one choice of ``extras``, over one block's workspace.

    Every value a stage reads or writes is in one workspace, a float64 array of ``slots`` rows of
    ``stride`` points each, flattened: point ``j`` of a block in slot ``s`` is element
    ``s * stride + j``; input column ``k`` (:data:`physics.kernel.POINT_INPUTS` then
    :func:`physics.kernel.material`'s factors) is slot ``k``. With one array and offsets fixed
    in the source, LLVM sees that no two rows overlap and vectorizes every loop without run-time
    checks.

    Attributes
    ----------
    source : str
        Python source of the functions ``prelude`` and ``stage_0`` ... ``stage_<levels - 1>``, each
        ``(n, w)``: a loop over the ``n`` points of a block of compiled arithmetic on the workspace
        ``w``. The prelude computes what depends on the material factors alone (run once a call
        when they are scalars, else before each block's stage 0). [-]
    levels : int
        Number of compiled stages. [1]
    stride : int
        Points between two slots of the workspace. [1]
    slots : int
        Slots of the workspace. [1]
    outputs : tuple
        For each output of :data:`physics.OUTPUTS`, its slot, or None for a constant. [-]
    constants : tuple
        (m, value) of each output ``m`` that is a constant (the extras when not computed). [-]
    vectorized : tuple
        For each level 1 ... levels - 1, the numpy calls run before that level's stage:
        (ufunc name, argument's slot, result's slot). [-]
    """

    source: str
    levels: int
    stride: int
    slots: int
    outputs: tuple
    constants: tuple
    vectorized: tuple


def plan(extras: bool, stride: int = 4104) -> Plan:
    """Trace :func:`physics.kernel.point_outputs` and cut it into stages.

    Parameters
    ----------
    extras : bool
        As in :func:`physics.kernel.point_outputs`.
    stride : int, default 4104
        Points between two slots of the workspace: at least the block's points, and best not a
        multiple of 512 (rows 4 KiB apart share the L1 cache's sets). [1]

    Returns
    -------
    Plan
        The stages and the workspace's layout.
    """
    traced = trace(extras)
    nodes, outputs = list(traced.nodes), list(traced.outputs)
    # The prelude (level -1) holds what depends on the material factors alone (uniform over a
    # call whose materials are scalars, so computed once); each other node's level counts the
    # numpy calls below it.
    materials = set(range(len(kernel.POINT_INPUTS), INPUTS))  # the inputs are the trace's first nodes
    level = []
    for index, (op, args) in enumerate(nodes):
        if op in ("input", "const"):
            level.append(-1 if op == "const" or index in materials else 0)
        elif op not in VECTORIZED and all(level[a] == -1 for a in args):
            level.append(-1)
        else:
            below = max((max(level[a], 0) for a in args), default=0)
            level.append(below + 1 if op in VECTORIZED else below)
    # Inputs have a slot each; what numpy computes, a node read by numpy or in another stage than
    # its own, and an output get one; the rest stays in registers.
    kept = {index for index, (op, _) in enumerate(nodes) if op in VECTORIZED}
    for index, (op, args) in enumerate(nodes):
        if op not in ("input", "const"):
            kept.update(a for a in args if nodes[a][0] not in ("input", "const")
                        and (op in VECTORIZED or level[a] != level[index]))
    kept.update(index for index in outputs if nodes[index][0] != "const")
    slot = {k: k for k in range(INPUTS)}
    slot.update(_allocate(nodes, level, kept - set(slot), set(outputs), len(slot)))
    levels = max(level) + 1
    vectorized = tuple(tuple((op, slot[args[0]], slot[index]) for index, (op, args) in enumerate(nodes)
                             if op in VECTORIZED and level[index] == stage)
                       for stage in range(1, levels))
    source = "\n\n".join(_stage_source(nodes, level, slot, stride, stage) for stage in range(-1, levels))
    return Plan(source, levels, stride, max(slot.values()) + 1,
                tuple(slot[index] if nodes[index][0] != "const" else None for index in outputs),
                tuple((m, float(nodes[index][1][0])) for m, index in enumerate(outputs)
                      if nodes[index][0] == "const"),
                vectorized)


def _allocate(nodes: list, level: list[int], kept: set[int], outputs: set[int], first: int) -> dict[int, int]:
    """A slot for each node of ``kept``, from ``first`` on, shared by nodes whose lives do not overlap.

    A block runs the prelude (phase 0), then stage 0 (1), level 1's numpy calls (2), stage 1 (3),
    and so on. A node lives from its phase to the last phase that reads it; an output until the
    block is stored, and what the prelude computes for the whole call. A slot is given again
    only in a later phase than its last reader's, so a loop never writes a slot it still reads.
    Fewer slots keep a larger block's workspace in the cache.
    """
    phase = [0 if lev < 0 else 2 * lev + (op not in VECTORIZED)
             for (op, _), lev in zip(nodes, level, strict=True)]
    last = {index: math.inf if index in outputs or level[index] < 0 else phase[index] for index in kept}
    for index, (op, args) in enumerate(nodes):
        if op not in ("input", "const"):
            for a in args:
                if a in last:
                    last[a] = max(last[a], phase[index])
    free, live, slot, count = [], [], {}, first
    for index in sorted(kept, key=lambda i: (phase[i], i)):
        for ended in [other for other in live if last[other] < phase[index]]:
            live.remove(ended)
            heapq.heappush(free, slot[ended])
        if free:
            slot[index] = heapq.heappop(free)
        else:
            slot[index], count = count, count + 1
        live.append(index)
    return slot


def _stage_source(nodes: list, level: list[int], slot: dict[int, int], stride: int, stage: int) -> str:
    """The loop of one compiled stage: its nodes in trace order, each node with a slot stored there."""
    lines, known = [], set()

    def value(index: int) -> str:
        op, args = nodes[index]
        if op == "const":
            return _literal(args[0])
        if index not in known:  # an input or an earlier stage's node: read once per point
            known.add(index)
            lines.append(f"v{index} = w[{slot[index] * stride} + j]")
        return f"v{index}"

    for index, (op, args) in enumerate(nodes):
        if level[index] != stage or op in ("input", "const") or op in VECTORIZED:
            continue
        operands = [value(a) for a in args]
        expression = f"np.sqrt({operands[0]})" if op == "sqrt" else f" {_INFIX[op]} ".join(operands)
        lines.append(f"v{index} = {expression}")
        known.add(index)
        if index in slot:
            lines.append(f"w[{slot[index] * stride} + j] = v{index}")
    body = "\n".join("        " + line for line in lines) or "        pass"
    name = "prelude" if stage < 0 else f"stage_{stage}"
    return f"def {name}(n, w):\n    for j in range(n):\n{body}\n"


def _literal(value) -> str:
    if isinstance(value, bool):
        return "1.0" if value else "0.0"
    value = float(value)
    if math.isinf(value):
        return "np.inf" if value > 0 else "-np.inf"
    return repr(value)
