"""The C allocator's arenas, capped for a process that runs for days.

glibc gives each thread that contends for ``malloc`` an arena of its own, up to eight per
core, and an arena keeps most of what was freed in it. The service's threads (zenoh's
runtime, the planner's worker, the loop) then each hold on to their own high-water mark:
under floods of 10,000 queries its RSS swung by 20 MiB from one flood to the next and its
floor crept up by about 1 MiB a flood (20 floods, 237 to 258 MiB), while the Python heap
stayed flat (tracemalloc) and a bare zenoh queryable under the same floods stayed at
30 MiB. With two arenas the floor stayed flat over the same 20 floods (240-242 MiB) and the
swing halved. ``MALLOC_ARENA_MAX`` in the environment, glibc's own setting, wins.
"""

from __future__ import annotations

import ctypes
import os

M_ARENA_MAX = -8
"""``mallopt``'s parameter number for the arena cap (glibc's malloc.h)."""
ARENAS = 2


def cap_arenas(arenas: int = ARENAS) -> bool:
    """Cap the C allocator's arenas unless ``MALLOC_ARENA_MAX`` says otherwise; True when
    the cap is now in force. Call it before the threads start: an arena made already stays.
    Without glibc (musl's ``mallopt`` does nothing, macOS has none) nothing changes."""
    if "MALLOC_ARENA_MAX" in os.environ:
        return False
    mallopt = getattr(ctypes.CDLL(None), "mallopt", None)
    return mallopt is not None and mallopt(M_ARENA_MAX, arenas) == 1
