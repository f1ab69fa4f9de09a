"""Memory is checked before it is allocated.

A setting such as a 0.001 mm voxel or a billion particles asks for arrays that no machine
holds; allocating them first would grow the process until the kernel kills it, or swap
the machine to a halt. Every stage that sizes its arrays from a user's setting estimates
them first with :func:`check_memory` and refuses, naming the setting, with the estimate
and what is free.
"""

from __future__ import annotations

import os

from hifumotion.errors import InputError

#: Part of the available memory one request may take: the rest is for everything else.
USABLE_FRACTION = 0.8
#: Most frames one run records or images. A run's frames are all held in memory (the particles'
#: trajectories, the images) and each costs solver steps: 10⁵ is 83 min at 20 frames/s, far
#: beyond any push the model describes, and a 10⁻¹² s interval or a 10⁹ s run is refused by it
#: before anything is allocated.
MAX_FRAMES = 100_000


def available_memory_bytes() -> int:
    """Memory the system can give this process now (bytes): ``MemAvailable`` on Linux,
    else free physical pages; a cgroup limit lowers it where one is set."""
    available = None
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    available = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError):
        available = None
    if available is None:
        try:
            available = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            available = 1 << 62          # unknown: do not refuse
    for limit_file, usage_file in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            with open(limit_file, encoding="ascii") as fh:
                text = fh.read().strip()
            if text == "max":
                continue
            with open(usage_file, encoding="ascii") as fh:
                used = int(fh.read().strip())
            available = min(available, max(int(text) - used, 0))
        except (OSError, ValueError):
            continue
    return int(available)


def format_bytes(n: float) -> str:
    """``1.5 GB``-style text (powers of 1024)."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1024 or unit == "PB":
            if unit == "B":
                return f"{n:.0f} {unit}"
            return f"{n:.1f} {unit}" if abs(n) < 1e6 else f"{n:.3g} {unit}"   # 10³⁰⁰ PB in a few digits
        n /= 1024.0
    return f"{n:.1f} PB"


def check_memory(estimate_bytes: float, what: str, field: str) -> None:
    """Raise :class:`~hifumotion.errors.InputError` naming ``field`` when ``what`` would need
    more than :data:`USABLE_FRACTION` of the available memory (``estimate_bytes``)."""
    free = available_memory_bytes()
    if not estimate_bytes <= USABLE_FRACTION * free:
        raise InputError(f"{what} would need about {format_bytes(estimate_bytes)} of memory and "
                         f"{format_bytes(free)} is free; choose a coarser setting", field)


__all__ = ["available_memory_bytes", "check_memory", "format_bytes", "MAX_FRAMES", "USABLE_FRACTION"]
