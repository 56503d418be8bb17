"""The command's allocator setting: large blocks from the heap, kept when freed."""

from __future__ import annotations

import ctypes
import subprocess
import sys

import pytest

# A 64 MB block, and glibc's count of bytes in mmapped blocks (mallinfo2's hblkhd) around it.
PROBE = """
import ctypes, sys
from usd_garment.cli.allocator import keep_freed_memory

class Info(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks",
                 "uordblks", "fordblks", "keepcost")]

libc = ctypes.CDLL(None)
libc.mallinfo2.restype = Info
applied = keep_freed_memory() if sys.argv[1] == "keep" else False
block = ctypes.create_string_buffer(64 << 20)
mapped = libc.mallinfo2().hblkhd
del block
print(applied, mapped >= 64 << 20, libc.mallinfo2().arena >= 64 << 20)
"""


def _probe(mode: str, env: dict[str, str] | None = None) -> list[str]:
    return subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True,
                          check=True, env=env).stdout.split()  # fmt: skip


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or not hasattr(ctypes.CDLL(None), "mallinfo2"),
    reason="glibc's malloc only",
)
def test_large_blocks_come_from_the_heap_and_stay_there() -> None:
    # By default a 64 MB block is mmapped (and unmapped when freed); after the setting it comes
    # from the heap, which keeps it when it is freed.
    assert _probe("plain") == ["False", "True", "False"]
    assert _probe("keep") == ["True", "False", "True"]
    # A user's own malloc tuning in the environment is left alone.
    assert _probe("keep", {"MALLOC_ARENA_MAX": "2", "PATH": ""})[0] == "False"
