"""The waveform registry: every waveform module's declaration, and what the scene, renderer and docs derive from it.

A waveform module states ``NAME`` (the scene's ``[illumination] waveform``),
``SUMMARY`` (one line for the docs), ``PARAMETERS`` (its keys as
:class:`~analytic.waveforms.waveform.Parameter`: kind, unit, default and the
renderer plugins' property) and ``build(illumination, period) -> Waveform``;
optionally ``plugin_entries(illumination, period) -> dict`` where its plugin
properties are not its keys one to one (the square's resolved width, the
sampled response's samples as text). :data:`WAVEFORMS` holds them by name;
the scene's schema (:class:`analytic.scenes.common.Illumination`: names, own
keys, checks), the XML export (:func:`plugin_entries`), the plugins' reading
of their properties (:func:`illumination_options`) and the plugins' docs
(:func:`plugin_rows`) read nothing else. A new waveform is one module listed
in :data:`MODULES` (or passed to :func:`register`) and its tests.
"""

from __future__ import annotations

from . import butterworth, emg, gaussian, impulse, sampled, sech2, square
from .waveform import Waveform

__all__ = ["make_waveform", "register", "WAVEFORMS", "BUILDERS", "MODULES", "keys", "own_keys", "parameter",
           "plugin_entries", "illumination_options", "plugin_rows"]

#: The project's waveform modules, in the order the docs list them.
MODULES = (impulse, square, butterworth, gaussian, emg, sech2, sampled)

#: The scene's ``[illumination] waveform`` -> its module (filled by :func:`register`).
WAVEFORMS: dict = {}
#: The same registry under its former name.
BUILDERS = WAVEFORMS


def register(module):
    """Add a waveform module to :data:`WAVEFORMS` after checking its declaration; returns the module.

    Raises
    ------
    ValueError
        A name taken, a missing ``build``, or a key declared with another kind than another waveform's.
    """
    name = module.NAME
    if name in WAVEFORMS:
        raise ValueError(f"waveform {name!r} is registered already")
    if not callable(getattr(module, "build", None)) or not isinstance(module.SUMMARY, str):
        raise ValueError(f"waveform {name!r}: a module needs NAME, SUMMARY, PARAMETERS and build()")
    for item in module.PARAMETERS:
        known = _declared().get(item.name)
        if known is not None and (known.kind, known.plugin) != (item.kind, item.plugin):
            raise ValueError(f"waveform {name!r}: key {item.name!r} is declared by another waveform as "
                             f"{known.kind} (plugin property {known.plugin!r})")
    WAVEFORMS[name] = module
    return module


def _declared() -> dict:
    declared = {}
    for module in WAVEFORMS.values():
        for item in module.PARAMETERS:
            declared.setdefault(item.name, item)
    return declared


def keys() -> tuple:
    """Every optional ``[illumination]`` key of the registered waveforms, in declaration order."""
    return tuple(_declared())


def own_keys(name: str) -> tuple:
    """The keys waveform ``name`` takes."""
    return tuple(item.name for item in WAVEFORMS[name].PARAMETERS)


def parameter(key: str):
    """The :class:`~analytic.waveforms.waveform.Parameter` declared for ``key``."""
    return _declared()[key]


def make_waveform(illumination, period: float) -> Waveform:
    """The waveform of an illumination, with defaults resolved against the period.

    Parameters
    ----------
    illumination : analytic.Illumination
        The scene's ``[illumination]`` table.
    period : float
        Sampling period T, metres; sets the defaults (square width T/5,
        Butterworth cutoff 1/(2T), duration 3/cutoff, order 3). The
        Gaussian, EMG, sech² and sampled pulses have no default.

    Returns
    -------
    Waveform

    Raises
    ------
    SceneError
        A parameter its waveform cannot deliver in float64 (each module
        names its bounds).
    """
    return WAVEFORMS[illumination.waveform].build(illumination, period)


def plugin_entries(illumination, period: float) -> dict:
    """The renderer plugins' properties for an illumination: ``waveform`` and the scene's own keys, as declared.

    Defaults are left to the plugin, which builds the waveform with the same
    :func:`make_waveform` and period; a module's own ``plugin_entries``
    (when it has one) gives its properties instead.
    """
    module = WAVEFORMS[illumination.waveform]
    entries = {"waveform": illumination.waveform}
    if hasattr(module, "plugin_entries"):
        entries.update(module.plugin_entries(illumination, period))
        return entries
    for item in module.PARAMETERS:
        value = getattr(illumination, item.name)
        if value is not None and item.plugin is not None:
            entries[item.plugin] = int(value) if item.kind == "integer" else float(value)
    return entries


def illumination_options(read) -> dict:
    """``Illumination`` keyword arguments from the plugins' properties (the inverse of :func:`plugin_entries`).

    Parameters
    ----------
    read : callable
        ``read(property)``: the property's value, or None when absent.

    Raises
    ------
    ValueError
        A ``samples`` property that is not comma-separated numbers.
    """
    options = {}
    for item in _declared().values():
        if item.plugin is None:
            continue
        value = read(item.plugin)
        if item.kind == "samples" and value is not None:
            try:
                value = [float(number) for number in str(value).split(",")]
            except ValueError:
                raise ValueError("samples must be comma-separated numbers") from None
        options[item.name] = value
    return options


def plugin_rows() -> str:
    """The rows of the plugins' ``pluginparameters`` table for the waveform and its properties (reST)."""
    names = ", ".join(f"``{name}``" for name in WAVEFORMS)
    rows = ["     * - waveform", "       - |string|",
            f"       - Source intensity waveform s(t): {names} (Default: ``impulse``). Each bin receives",
            "         κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ) of its path length τ."]
    properties: dict = {}
    for name, module in WAVEFORMS.items():
        for item in module.PARAMETERS:
            if item.plugin is not None:
                properties.setdefault(item.plugin, (item, []))[1].append(name)
    for plugin, (item, users) in properties.items():
        kind = "|int|" if item.kind == "integer" else "|string|" if item.kind == "samples" else "|float|"
        unit = f", {item.unit}" if item.unit else ""
        rows += [f"     * - {plugin}", f"       - {kind}",
                 f"       - {', '.join(f'``{user}``' for user in users)}: ``{item.name}``{unit} "
                 f"(Default: {item.default})."]
    return "\n".join(rows)


for _module in MODULES:
    register(_module)
