"""tal (y-tal 0.20): its render configuration as a scene, the OBJ meshes it names, its HDF5 capture layout.

- :mod:`.config`: a ``tal render`` YAML file as the relay-wall scene tal renders (:class:`TalScene`);
- :mod:`.geometry`: the configuration's geometries, their poses and checks;
- :mod:`.mesh`: a planar OBJ polygon as a rectangle and its indicator image;
- :mod:`.capture`: tal's HDF5 capture (``transient.h5``), written for a plane and read for every layout;
- :mod:`.relay_wall_capture`: a relay-wall transient in the layout ``tal render`` writes;
- :mod:`.scene_capture`: any scene's transient in its kind's layout;
- :mod:`.formats`: these files in the model's format registry (:mod:`analytic.formats`), by suffix.

Names are loaded on first use (``lazy_loader``); ``__all__`` lists the public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "config": ["TalScene", "TalConfigWarning", "load_tal_config", "tal_config_scene", "TAL_DEFAULTS", "TAL_VERSION"],
    "capture": ["Capture", "CaptureError", "write_capture", "read_capture", "H_FORMATS", "GRID_FORMATS",
                "VOLUME_FORMATS", "ACCOUNTS_FIRST_AND_LAST_BOUNCES"],
    "relay_wall_capture": ["write_relay_wall_capture", "relay_wall_layout"],
    "scene_capture": ["write_scene_capture"],
})
