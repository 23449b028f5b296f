"""Other tools' files: tal's YAML scenes, OBJ meshes and HDF5 captures; Mitsuba 3 / mitransient XML and films.

The exact model (:mod:`analytic`) imports none of it: where a user hands it
one of these files (a tal configuration as a scene, a tal histogram as an
instrument response, a transient written as tal's HDF5), it asks its format
registry (:mod:`analytic.formats`), which :mod:`interop.tal.formats` fills
as the package's entry point, on first use.
Two sub-packages, one per tool family:

- :mod:`interop.tal`: tal's render configuration (YAML) and the OBJ meshes
  it names, read as the relay-wall scene tal renders; tal's HDF5 capture
  layout, written and read;
- :mod:`interop.mitransient`: a scene as Mitsuba 3 XML for our plugins or
  mitransient's, mitransient's developed films read as transients, and what
  its NLOS integrator renders (the model plus its ray offsets).

Names are loaded on first use (``lazy_loader``, as in every package of this
project); ``__all__`` lists the public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "tal.config": ["TalScene", "TalConfigWarning", "load_tal_config"],
    "tal.capture": ["Capture", "CaptureError", "write_capture", "read_capture"],
    "tal.relay_wall_capture": ["write_relay_wall_capture"],
    "mitransient.export": ["export_scene"],
})
