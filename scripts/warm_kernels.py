"""Compile (or load from Numba's cache) the kernels that only the tests and diagnosis call.

``scripts/setup.sh`` runs this beside its warm-up of the main job (which
compiles A's assembly), so that the two compiles share the machine's cores
instead of the first test paying minutes: :func:`analytic.system.pair_entries`
by every route (each route is held to the adaptive one by the tests). The
values computed are discarded.
"""

from __future__ import annotations

import contextlib

from analytic.scene import default_scene
from analytic.system import METHODS, pair_entries


def main() -> None:
    scene = default_scene(pixels=4, noise=None)
    for method in METHODS:
        for taylor in (True, False):
            with contextlib.suppress(ValueError):      # a route that does not apply here is still compiled
                pair_entries(scene, 0, 5, method=method, taylor=taylor)


if __name__ == "__main__":
    main()
