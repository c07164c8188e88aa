"""Throughput of physics.evaluate against one numpy.power pass, and the cost of one point, side by side.

Run: ``python bench/physics.py [--points N] [--repeats R]`` (about 20 s with the defaults).

Large calls: each repeat times, interleaved so that every case sees the same machine load,
one ``numpy.power`` pass over N points and ``physics.evaluate`` on N random design points
returning all 21 outputs and μ alone (``outputs=["mu"]``: the same arithmetic, one array
stored), each on one thread per usable CPU (``ExecutionOptions(threads=..., executor=pool)``,
what the service passes down by default) and on one thread (the library's default).
Printed per case: min / median / max of the time over the repeats, of its ratio to the same
repeat's ``numpy.power`` pass, and of the CPU time the process spent per wall-clock second
("cores busy": near 2 when both cores work), and of its process CPU time over that of the same
repeat's ``numpy.power`` pass ("CPU ratio": the work, which preemption by other processes on a
shared machine does not inflate; one thread's CPU ratio is its wall ratio on a quiet core); then
the speed-up from the extra threads (one-thread time over threaded time, per repeat), beside that
of a perfectly parallel reference (the ``numpy.power`` pass split in two halves on two threads)
and of two processes against one running pure-Python arithmetic (no shared memory, no GIL: what
the machine gives two independent workers): when these references are well below 2, the machine
did not give the process a second core, and no code can use it. A last reference writes the
(21, N) float64 result of an all-outputs call into new memory with no arithmetic (``numpy.empty``
then ``fill``): the part of that call no kernel avoids, since the operating system hands a process
new pages zeroed at their first write.
Targets of issue 35: μ alone <= 3x, all outputs <= 4x (both cores).

One point: each repeat times a batch of ``physics.evaluate`` calls of one scalar point
(every input checked against the parameter table), the same of ``physics.evaluate_point`` (the
same point as Python floats, what ``/v1/friction`` calls) and a batch of one-element numpy ufunc
calls, in wall-clock and in process CPU time (which preemption by other work does not
inflate). Target: <= 25 us per point.

numba's first call: the wall-clock time of a fresh process importing the package and making one
compiled call, in two successive processes (the first may compile; later ones load numba's cache
of the generated stages, written beside the package).

The machine's CPU count and load average are printed before and after: a figure measured
while other work ran says so.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

# Run as a script, this file's folder comes first on sys.path and its name would
# shadow the package it measures.
if Path(sys.path[0]).resolve() == Path(__file__).resolve().parent:
    sys.path.pop(0)

import numpy as np

from microbearing import physics

USABLE_CPUS = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
POINT = {"balls": 4, "load_N": 0.008826, "speed_m_s": 0.05}


def random_design_points(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Random designs over a broad domain: every design and operating input varies."""
    rng = np.random.default_rng(seed)
    return {
        "balls": rng.integers(3, 41, n).astype(float),
        "groove_angle_deg": rng.uniform(30.0, 75.0, n),
        "load_N": 10 ** rng.uniform(-3, np.log10(0.05), n),
        "speed_m_s": rng.uniform(0.0, 0.2, n),
        "balls_touching": rng.random(n) < 0.5,
        "mu_pivot": rng.uniform(0.1, 1.0, n),
        "adhesion_energy_J_m2": rng.uniform(0.0, 0.3, n),
    }


def machine() -> str:
    """CPU count and the 1, 5 and 15 minute load averages."""
    load = ", ".join(f"{value:.2f}" for value in os.getloadavg())
    return f"{os.cpu_count()} CPUs ({USABLE_CPUS} usable), load average {load}"


def spread(values: list[float], scale: float = 1.0, digits: int = 1) -> str:
    """'min / median / max' of ``values`` times ``scale``."""
    summary = (min(values), statistics.median(values), max(values))
    return " / ".join(f"{v * scale:.{digits}f}" for v in summary)


def timed(call) -> tuple[float, float]:
    """Wall-clock and process CPU seconds of ``call()``."""
    cpu, start = time.process_time(), time.perf_counter()
    call()
    return time.perf_counter() - start, time.process_time() - cpu


def kernels(blocks: list[int]) -> list[tuple[str, str, int]]:
    """(label, kernel, block points) of each kernel: numpy at each block size, then numba if installed."""
    numpy_kernels = [(f"numpy {size // 1024}k blocks", "numpy", size) for size in blocks]
    numba_kernel = [("numba", "numba", physics.bearing._BLOCK_POINTS)] if physics.compiled.AVAILABLE else []
    return numpy_kernels + numba_kernel


def _spin(n: int) -> float:
    """Pure-Python arithmetic: one core's work with no memory traffic and no shared state."""
    total = 0.0
    for i in range(n):
        total += i * 0.5
    return total


def process_reference(repeats: int, n: int = 2_000_000) -> list[float]:
    """Per repeat, the throughput of two processes running :func:`_spin` over that of one [1]."""
    ratios = []
    with ProcessPoolExecutor(2) as pool:
        list(pool.map(_spin, [1000, 1000]))  # start both workers
        for _ in range(repeats):
            one = timed(lambda: pool.submit(_spin, n).result())[0]
            two = timed(lambda: list(pool.map(_spin, [n, n])))[0]
            ratios.append(2.0 * one / two)
    return ratios


def large_calls(points: int, repeats: int, blocks: list[int]) -> None:
    processes = process_reference(repeats)  # before this process starts threads, which fork would copy
    inputs = random_design_points(points)
    base = inputs["load_N"]
    chosen = kernels(blocks)
    cases = {(label, outputs, threads): {"wall": [], "cores": [], "work": []} for label, _, _ in chosen
             for outputs in ("all 21 outputs", "mu only") for threads in ("", "1")}
    power, power_split, power_cpus, fresh = [], [], [], []
    halves = np.array_split(base, 2)
    pool = ThreadPoolExecutor(2)
    physics_pool = ThreadPoolExecutor(USABLE_CPUS, thread_name_prefix="physics")
    default_block = physics.bearing._BLOCK_POINTS

    def execution(kernel: str, threads: str) -> physics.ExecutionOptions:
        if threads:
            return physics.ExecutionOptions(kernel)
        return physics.ExecutionOptions(kernel, USABLE_CPUS, physics_pool if USABLE_CPUS > 1 else None)

    for _, kernel, size in chosen:  # warm up: pool threads, caches, numba's compilation (both variants)
        physics.bearing._BLOCK_POINTS = size
        for wanted in (None, ["mu"]):
            physics.evaluate(outputs=wanted, execution=execution(kernel, ""), **inputs)
    for _ in range(repeats):
        power_wall, power_cpu = timed(lambda: np.power(base, 0.47))
        power.append(power_wall)
        power_cpus.append(power_cpu)
        power_split.append(timed(lambda: list(pool.map(lambda half: np.power(half, 0.47), halves)))[0])
        # the floor of an all-outputs call: writing its 21 rows of new memory, nothing computed
        fresh.append(timed(lambda: np.empty((len(physics.OUTPUTS), points)).fill(1.0))[0])
        for label, kernel, size in chosen:
            # the block size is a private constant of the kernel: set here to compare sizes in one run
            physics.bearing._BLOCK_POINTS = size
            for outputs in ("all 21 outputs", "mu only"):
                for threads in ("", "1"):
                    wanted = ["mu"] if outputs == "mu only" else None
                    options = execution(kernel, threads)
                    wall, cpu = timed(lambda wanted=wanted, options=options: physics.evaluate(
                        outputs=wanted, execution=options, **inputs))
                    cases[(label, outputs, threads)]["wall"].append(wall)
                    cases[(label, outputs, threads)]["cores"].append(cpu / wall)
                    cases[(label, outputs, threads)]["work"].append(cpu / power_cpu)
    physics.bearing._BLOCK_POINTS = default_block
    print(f"large calls: {points:,} points (7 of 16 inputs varied per point), {repeats} repeats; "
          "min / median / max")
    print(f"  numpy.power pass                                    {spread(power, 1e3):>22s} ms")
    for (label, outputs, threads), times in cases.items():
        case = f"{label}, {outputs}, {'one thread' if threads else f'{USABLE_CPUS} threads'}"
        ratios = [t / p for t, p in zip(times["wall"], power, strict=True)]
        print(f"  {case:50s}{spread(times['wall'], 1e3):>22s} ms   ratio {spread(ratios):>18s}"
              f"   cores busy {spread(times['cores'], digits=2)}   CPU ratio {spread(times['work'])}")
    floor = [f / p for f, p in zip(fresh, power, strict=True)]
    case = f"writing {len(physics.OUTPUTS)} rows of new memory (reference)"
    print(f"  {case:50s}{spread(fresh, 1e3):>22s} ms   ratio {spread(floor):>18s}")
    reference = [one / split for one, split in zip(power, power_split, strict=True)]
    print(f"  speed-up of numpy.power split over two threads (reference)     {spread(reference, digits=2)}")
    print(f"  two processes of pure-Python arithmetic over one (reference)   {spread(processes, digits=2)}")
    for label, _, _ in chosen:
        for outputs in ("all 21 outputs", "mu only"):
            one, default = cases[(label, outputs, "1")]["wall"], cases[(label, outputs, "")]["wall"]
            speedup = [a / b for a, b in zip(one, default, strict=True)]
            print(f"  speed-up from {USABLE_CPUS} threads, {label + ', ' + outputs:40s}         "
                  f"{spread(speedup, digits=2)}")
    print("  targets (issue 35): mu only ratio <= 3, all 21 outputs <= 4 (both cores)")
    if not physics.compiled.AVAILABLE:
        print("  numba is not installed (pip install microbearing[fast]): the numba kernel was not measured")


def single_points(repeats: int, calls: int = 2000) -> None:
    one = np.ones(1)
    cases = {"physics.evaluate": lambda: physics.evaluate(**POINT),
             "physics.evaluate_point": lambda: physics.evaluate_point(**POINT),
             "numpy.add of 1-element arrays": lambda: np.add(one, one)}
    wall = {label: [] for label in cases}
    cpu = {label: [] for label in cases}
    physics.evaluate(**POINT)
    for _ in range(repeats):
        for label, call in cases.items():
            spent = timed(lambda call=call: [call() for _ in range(calls)])
            wall[label].append(spent[0] / calls)
            cpu[label].append(spent[1] / calls)
    print(f"one point ({POINT}, every input checked), {repeats} repeats of {calls} calls; min / median / max "
          "per call (CPU time: what preemption by other work does not inflate)")
    for label in cases:
        print(f"  {label:30s} wall {spread(wall[label], 1e6, 2):>22s} us   "
              f"CPU {spread(cpu[label], 1e6, 2):>22s} us")
    print("  target: physics.evaluate <= 25 us")


#: A fresh process's first compiled call: import, numba's import, its compilation or cache load.
_FIRST_CALL = """
import time
start = time.perf_counter()
import numpy as np
from microbearing import physics
physics.evaluate(balls=np.full(200_000, 4.0), load_N=1e-2, speed_m_s=0.1, outputs=["mu"],
                 execution=physics.ExecutionOptions("numba"))
print(time.perf_counter() - start)
"""


def first_calls(processes: int = 2) -> None:
    """Wall-clock seconds of a fresh process's import and first numba call, in successive processes."""
    if not physics.compiled.AVAILABLE:
        return
    seconds = [float(subprocess.run([sys.executable, "-c", _FIRST_CALL], capture_output=True, text=True,
                                    check=True).stdout) for _ in range(processes)]
    print("numba's first call in a fresh process (import, then compilation or its cache beside the package), "
          f"successive processes: {', '.join(f'{s:.2f}' for s in seconds)} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--blocks", default=str(physics.bearing._BLOCK_POINTS),
                        help="comma-separated block sizes (points) of the numpy kernel to compare, e.g. "
                             "4096,16384,65536")
    args = parser.parse_args()
    print(f"before: {machine()}")
    large_calls(args.points, args.repeats, [int(size) for size in args.blocks.split(",")])
    single_points(args.repeats)
    first_calls()
    print(f"after:  {machine()}")


if __name__ == "__main__":
    main()
