"""The exact forward model of diffuse imaging, and the reconstruction that inverts it.

A user writes ``import analytic`` and then, for example::

    scene = analytic.load_scene("scene.toml")     # or analytic.default_scene()
    A = analytic.system_matrix(scene)             # sparse (K N, M²), exact to quadrature precision
    y = analytic.forward(scene, A)                # (K, N) samples y_k[n]
    result = analytic.reconstruct(A, analytic.add_noise(y, scene.noise), scene.pixels,
                                  rule="discrepancy", sigma=scene.noise.sigma)

Names are loaded on first use (``lazy_loader``, as in every package of this
project), so that ``import analytic`` stays cheap (no Numba) and the
command line starts fast; ``__all__`` lists the public API. Nothing here
imports Mitsuba, matplotlib or Dask. The files a command writes and reads
live in :mod:`analytic.files`, which the model itself never imports.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "errors": ["UserError", "SceneError", "ImageError", "DataError", "OptionError", "ResourceError"],
    "scenes.common": ["Scene", "Illumination", "Sampling", "Noise", "default_scene", "sensor_grid"],
    "scenes.relay_wall": ["RelayWallScene", "Scan", "default_relay_wall_scene"],
    "scenes.scene_file": ["load_scene", "scene_from_dict", "scene_to_tables", "read_toml"],
    "scenes.reflectance": ["builtin_reflectance", "read_reflectance"],
    "waveforms": ["Waveform", "make_waveform"],
    "binning": ["bin_index"],
    "attenuation": ["attenuation"],
    "measurement.noise": ["add_noise"],
    "measurement.detector": ["Detector", "expected_counts", "draw_counts", "coates_estimate"],
    "operator.system": ["system_matrix", "count_entries", "QuadratureWarning"],
    "operator.matrix_free": ["forward"],
    "operator.offset_operator": ["capture_operator"],
    "operator.response": ["impulse_response", "binned_contour_model"],
    "operator.window": ["response_range", "covering_sampling", "window_share", "WindowWarning"],
    "files": ["build_meta", "write_transient", "read_transient"],
    "inversion": ["reconstruct", "reconstruct_rules", "reconstruct_tv", "Reconstruction", "image_metrics",
                  "flat_image_psnr", "lambda_grid", "RULES", "RankDeficiencyWarning", "NoiseLimitWarning",
                  "RegularizationWarning"],
    "operator.conditioning": ["singular_values", "conditioning_summary"],
    "operator.derivatives": ["jacobian"],
    "operator.sensitivity": ["EdgeOnArrivalWarning"],
    "inversion.bounds": ["crb", "Bounds"],
    "operator.parameters": ["with_values"],
})
