"""What a speed figure was measured on: the processor, and three short readings of its speed.

This project's machines are lent as they come: two of the same 2-core kind (the same processor
name) ran the same code at 945 and 322 frames/s (docs/judge.md, stops 57 and 73). A figure
carries its machine's readings so that figures from two sessions can be told apart by the
machine before anyone looks for a cause in the code.
"""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from pathlib import Path

import torch

#: Floats of the large addition (40 MB a tensor: beyond any cache).
LARGE = 10_000_000
#: Floats of the small addition (its time is the fixed cost of one tensor operation).
SMALL = 1_000
#: Side of the square float32 product.
SIDE = 1_000


def processor_name() -> str:
    """The processor's model name (Linux: ``/proc/cpuinfo``), else what ``platform`` says."""
    info = Path("/proc/cpuinfo")
    if info.exists():
        for line in info.read_text().splitlines():
            if line.startswith("model name"):
                return line.partition(":")[2].strip()
    return platform.processor() or platform.machine()


def describe_machine() -> str:
    """E.g. ``"x86_64, AMD EPYC, 2 cores, torch 2.13.0+cpu, 2 threads"``."""
    return (
        f"{platform.machine()}, {processor_name()}, {os.cpu_count()} cores, "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads"
    )


def _best(run: Callable[[], object], repeat: int) -> float:
    """The fastest of ``repeat`` timings (s) of ``run()``."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def speed_readings() -> dict[str, float]:
    """Three readings of this machine's speed (about 0.2 s in all; the fastest of several
    runs each): ``large_add_ms``, a 10-million-float ``x + y`` into a tensor already touched
    (memory bandwidth); ``small_op_us``, a 1,000-float ``x + y`` (the fixed cost of one tensor
    operation, which the preimage push pays about 400 times a step); ``matmul_gflops``, a
    1,000² float32 product (the networks)."""
    x, y = torch.rand(LARGE), torch.rand(LARGE)
    out = torch.empty_like(x)
    large = _best(lambda: torch.add(x, y, out=out), 5)
    a, b = torch.rand(SMALL), torch.rand(SMALL)
    small = _best(lambda: [a + b for _ in range(1000)], 5) / 1000
    m = torch.rand(SIDE, SIDE)
    product = _best(lambda: m @ m, 5)
    return {
        "large_add_ms": 1e3 * large,
        "small_op_us": 1e6 * small,
        "matmul_gflops": 2 * SIDE**3 / product / 1e9,
    }
