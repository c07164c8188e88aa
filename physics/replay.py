"""The numpy kernel: :func:`physics.kernel.point_outputs` traced once and replayed as numpy ufunc calls.

Run on numpy arrays directly, the equation functions allocate a fresh array for every operation
and the outputs are then copied into the call's result: on large calls fresh memory costs more
than the arithmetic. Here the trace of the same functions (:func:`physics.fused.trace`, from
which the numba kernel is generated too) becomes a :class:`Program` for the inputs a call varies:
what depends only on scalars is computed once a call on Python numbers (as the equation functions
fold it), every other operation is one numpy ufunc writing into a row of a block-sized workspace
(rows given again once their last reader has run) or straight into the result's row of an output
asked for; what no output asked for needs is not run. The operations, their order and their
operands are those of the equation functions on arrays, so the results are theirs bit for bit
(tested); no equation is written here. Calls below ``physics.bearing``'s ``_REPLAY_POINTS`` run
the functions on the arrays themselves (fewer Python steps).
"""

from __future__ import annotations

import functools
import operator
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from . import elementary, fused

__all__ = ["Program", "program", "runner"]

#: The numpy ufunc of each operation of the trace on arrays.
_UFUNCS = {"add": np.add, "sub": np.subtract, "mul": np.multiply, "truediv": np.divide,
           "ge": np.greater_equal, "sqrt": np.sqrt, **fused.VECTORIZED}
#: The same operations on Python numbers: what the equation functions do with scalar operands.
_SCALAR = {"add": operator.add, "sub": operator.sub, "mul": operator.mul, "truediv": operator.truediv,
           "ge": operator.ge, "sqrt": elementary.sqrt, "tan": elementary.tan, "cbrt": elementary.cbrt,
           "log": elementary.log, "exp": elementary.exp}


@dataclass(frozen=True)
class Program:
    """The numpy calls of one block, for one choice of ``extras``, varying inputs and outputs asked for.

    Every value is a node of :func:`physics.fused.trace` (its index); a node that depends only on
    scalars is a scalar, the others are arrays of the block's length.

    Attributes
    ----------
    scalars : tuple
        (node, op, operand nodes) of each operation on scalars only, in trace order: computed on
        Python numbers once a call. [-]
    steps : tuple
        (ufunc, first operand's node, second operand's node or -1, node) of each array operation,
        in trace order. [-]
    slots : dict
        Workspace row of each array node that is not an input or an output asked for. [-]
    rows : dict
        Result row of each array node that is an output asked for (computed into it). [-]
    copies : tuple
        (row, node) of each row asked for that is not computed into: an output equal to an input,
        to a scalar or to another row's node; filled from that node. [-]
    size : int
        Rows of the workspace. [1]
    constants : tuple
        For every node after the inputs, a constant's value, else None. [-]
    """

    scalars: tuple
    steps: tuple
    slots: dict
    rows: dict
    copies: tuple
    size: int
    constants: tuple


@functools.lru_cache(maxsize=256)  # once a process, like the numba kernel's compiled stages
def program(extras: bool, varying: tuple[bool, ...], positions: tuple[int, ...]) -> Program:
    """The :class:`Program` of a call.

    Parameters
    ----------
    extras : bool
        As in :func:`physics.kernel.point_outputs`.
    varying : tuple of bool
        For each input of the trace (:data:`physics.kernel.POINT_INPUTS` then the material
        factors), whether it is an array. [-]
    positions : tuple of int
        Position in :data:`physics.OUTPUTS` of each output asked for, in the result's row order. [-]

    Returns
    -------
    Program
    """
    traced = fused.trace(extras)
    nodes, same = _shared(traced.nodes)
    wanted = [same[traced.outputs[position]] for position in positions]
    needed = set(wanted)  # what the outputs asked for read, directly or not: the rest is not run
    for index in range(len(nodes) - 1, -1, -1):
        if index in needed and nodes[index][0] not in ("input", "const"):
            needed.update(nodes[index][1])
    arrays = {index for index, flag in enumerate(varying) if flag}
    scalars, steps = [], []
    for index, (op, args) in enumerate(nodes):
        if op in ("input", "const") or index not in needed:
            continue
        if arrays.isdisjoint(args):
            scalars.append((index, op, args))
        else:
            arrays.add(index)
            steps.append((_UFUNCS[op], args[0], args[1] if len(args) > 1 else -1, index))
    rows, copies = {}, []
    for row, node in enumerate(wanted):
        if node in arrays and nodes[node][0] != "input" and node not in rows:
            rows[node] = row
        else:
            copies.append((row, node))
    slots, size = _slots(steps, rows)
    constants = tuple(args[0] if op == "const" else None for op, args in nodes[len(varying):])
    return Program(tuple(scalars), tuple(steps), slots, rows, tuple(copies), size, constants)


def _shared(nodes: tuple) -> tuple[list, list[int]]:
    """The nodes with each operand read from the first node of the same operation on the same operands
    (an expression the equation functions evaluate twice: eq 20's terms in F_S and in the breakdown of
    μ), and for each node that first one. The same operation on the same values gives the same bits."""
    first, same, shared = {}, [], []
    for index, (op, args) in enumerate(nodes):
        if op in ("input", "const"):
            key = (op, index) if op == "input" else (op, type(args[0]), repr(args[0]))
        else:
            args = tuple(same[a] for a in args)
            key = (op, args)
        same.append(first.setdefault(key, index))
        shared.append((op, args))
    return shared, same


def _slots(steps: list, rows: dict) -> tuple[dict, int]:
    """A workspace row for each computed node outside ``rows``, given again after its last reader.

    A step may write the row of an operand whose last reader it is: numpy's element-wise loops
    read each element before writing it. Every node outside ``rows`` has a reader (``steps``
    holds only what the outputs asked for need).
    """
    last = {}
    for step, (_, *args, _) in enumerate(steps):
        last.update((a, step) for a in args)
    free, slots, size = [], {}, 0
    for step, (_, *args, node) in enumerate(steps):
        for a in dict.fromkeys(args):
            if a in slots and last[a] == step:
                free.append(slots[a])
        if node in rows:
            continue
        if free:
            slots[node] = free.pop()
        else:
            slots[node], size = size, size + 1
    return slots, size


def runner(inputs: tuple, out: np.ndarray, positions: list[int], extras: bool,
           block: int) -> Callable[[int, int], None]:
    """``run(lo, hi)``: every output asked for at points ``lo:hi``, by blocks, into the rows of ``out``.

    Parameters
    ----------
    inputs : tuple
        The inputs of :data:`physics.kernel.POINT_INPUTS` then the factors of
        :func:`physics.kernel.material`: Python numbers, or 1-D arrays of the call's length. [SI]
    out : numpy.ndarray
        (outputs asked for, points) float64, written in place. [SI]
    positions : list of int
        Position in :data:`physics.OUTPUTS` of each row of ``out``. [-]
    extras : bool
        As in :func:`physics.kernel.point_outputs`.
    block : int
        Points per block: its workspace stays in the CPU's cache. [1]

    Returns
    -------
    callable
        ``run(lo, hi)``; calls on disjoint ranges may run in parallel threads (numpy releases
        the GIL in its loops), each with its own workspace. [-]
    """
    plan = program(extras, tuple(isinstance(v, np.ndarray) for v in inputs), tuple(positions))
    values = [*inputs, *plan.constants]  # by node: the inputs, then Python numbers and views
    for index, op, args in plan.scalars:  # what only scalars feed, once, as the functions fold it
        values[index] = _SCALAR[op](*[values[a] for a in args])
    varying = [index for index, value in enumerate(inputs) if isinstance(value, np.ndarray)]

    def run(lo: int, hi: int) -> None:
        workspace = np.empty((plan.size, min(block, max(hi - lo, 1))))
        env = values.copy()
        with np.errstate(divide="ignore"):  # per thread: log of a zero speed is -inf, exp(-inf) = 0
            for start in range(lo, hi, block):
                stop = min(start + block, hi)
                rows = workspace[:, :stop - start]
                for index in varying:
                    env[index] = inputs[index][start:stop]
                for node, slot in plan.slots.items():
                    env[node] = rows[slot]
                for node, row in plan.rows.items():
                    env[node] = out[row, start:stop]
                for ufunc, first, second, node in plan.steps:
                    if second < 0:
                        ufunc(env[first], env[node])
                    else:
                        ufunc(env[first], env[second], env[node])
                for row, node in plan.copies:
                    out[row, start:stop] = env[node]
    return run
