"""What this machine can hold: checked before anything large is allocated."""

from __future__ import annotations

import os

from .errors import ResourceError

__all__ = ["available_memory", "require_memory"]


def available_memory() -> int:
    """Bytes of memory available now (``MemAvailable``), or the physical memory if unknown."""
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))


def require_memory(needed: float, what: str, fix: str, *, limit: int | None = None) -> None:
    """Refuse, before allocating, a request that would not fit in memory.

    Parameters
    ----------
    needed : float
        Bytes the request needs.
    what : str
        What needs them, naming the key or option (``"plane.pixels = 100000"``).
    fix : str
        How to ask for less.
    limit : int, optional
        Bytes allowed; default half the memory available now.

    Raises
    ------
    ResourceError
        When ``needed`` exceeds ``limit``.
    """
    limit = available_memory() // 2 if limit is None else int(limit)
    if needed > limit:
        digits = 3
        while needed < 2**1000 and digits < 17 and f"{needed / 2**30:.{digits}g}" == f"{limit / 2**30:.{digits}g}":
            digits += 1         # as many digits as show the need above the limit
        size = f"{needed / 2**30:.{digits}g} GiB" if needed < 2**1000 else "more than 10^291 GiB"
        raise ResourceError(f"{what} needs {size} of memory, over the {limit / 2**30:.{digits}g} GiB available; "
                            f"{fix}")
