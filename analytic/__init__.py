"""The exact forward model of diffuse imaging, and the reconstruction that inverts it.

A user writes ``import analytic`` and then, for example::

    scene = analytic.load_scene("scene.toml")     # or analytic.default_scene()
    A = analytic.system_matrix(scene)             # sparse (K N, M²), exact to quadrature precision
    y = analytic.forward(scene, A)                # (K, N) samples y_k[n]
    result = analytic.reconstruct(A, analytic.add_noise(y, scene.noise), scene.pixels,
                                  rule="discrepancy", sigma=scene.noise.sigma)

Names are loaded on first use, so that ``import analytic`` stays cheap and
the command line starts fast; ``__all__`` lists the public API.
Nothing here imports Mitsuba, matplotlib or Dask.
"""

from __future__ import annotations

import importlib

# public name -> submodule that defines it
_EXPORTS = {
    "UserError": "errors", "SceneError": "errors", "ImageError": "errors", "DataError": "errors",
    "ResourceError": "errors",
    "Scene": "scene", "Illumination": "scene", "Sampling": "scene", "Noise": "scene",
    "default_scene": "scene", "sensor_grid": "scene",
    "load_scene": "scene_file", "scene_from_dict": "scene_file", "scene_to_tables": "scene_file",
    "read_toml": "scene_file",
    "builtin_reflectance": "reflectance", "read_reflectance": "reflectance",
    "Waveform": "waveforms", "make_waveform": "waveforms",
    "bin_index": "binning",
    "attenuation": "attenuation",
    "add_noise": "noise",
    "system_matrix": "system", "forward": "system", "count_entries": "system",
    "QuadratureWarning": "system",
    "impulse_response": "response", "binned_contour_model": "response",
    "response_range": "window", "covering_sampling": "window", "window_share": "window",
    "WindowWarning": "window",
    "build_meta": "io", "write_transient": "io", "read_transient": "io",
    "reconstruct": "inversion", "reconstruct_rules": "inversion", "reconstruct_tv": "inversion",
    "Reconstruction": "inversion", "image_metrics": "inversion", "flat_image_psnr": "inversion",
    "lambda_grid": "inversion", "RULES": "inversion", "RankDeficiencyWarning": "inversion",
    "RegularizationWarning": "inversion",
    "singular_values": "conditioning", "conditioning_summary": "conditioning",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'analytic' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
