"""Scene kinds: what the model integrates over, as validated frozen dataclasses, and their files.

- :mod:`.kinds`: the protocol every scene kind meets and the registry that names them;
- :mod:`.common`: the tables every kind shares (illumination, sampling, noise) and the plane scene;
- :mod:`.limits`: the float64 limits of heights and of the model's tolerance;
- :mod:`.relay_wall`: a capture through a relay wall (NLOS);
- :mod:`.scene_file`: TOML scene files <-> scenes;
- :mod:`.reflectance`: reflectance images (the built-in pattern, PNG and EXR).

Names are loaded on first use (``lazy_loader``, as in every package of this
project); ``__all__`` lists the public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "kinds": ["SceneKind", "SCENE_KINDS", "SceneKindError", "register_scene_kind", "is_scene", "for_kind"],
    "common": ["Scene", "Illumination", "Sampling", "Noise", "default_scene", "sensor_grid"],
    "relay_wall": ["RelayWallScene", "Scan", "default_relay_wall_scene"],
    "scene_file": ["load_scene", "scene_from_dict", "scene_to_tables", "read_toml"],
    "reflectance": ["builtin_reflectance", "read_reflectance"],
})
