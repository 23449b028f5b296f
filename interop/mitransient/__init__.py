"""Mitsuba 3 and mitransient: a scene as XML for either, mitransient's films, and its NLOS integrator's offsets.

- :mod:`.export`: a scene as a Mitsuba 3 XML file, for our plugins or for mitransient;
- :mod:`.export_relay_wall`: a relay-wall capture as XML (our ``transient_opl_nlos`` or ``transient_nlos_path``);
- :mod:`.nlos`: what mitransient's ``transient_nlos_path`` renders: the exact model plus its ray offsets.

No module here imports Mitsuba to write a file. Names are loaded on first
use (``lazy_loader``); ``__all__`` lists the public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "export": ["export_scene", "FORMATS", "RADIUS", "SPP", "SPP_RELAY_WALL", "MITRANSIENT_IMPULSE_ONLY"],
    "export_relay_wall": ["MITRANSIENT_SCANS"],
    "nlos": ["emulated_estimates", "spawn_offset_difference", "moved_read_points", "offset_model",
             "EMULATED_SAMPLES", "EDGE_POINTS"],
})
