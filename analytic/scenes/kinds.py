"""Scene kinds: the protocol every kind meets, and the registry that names them.

A scene kind (the plane of docs/design.md section 1, the relay-wall capture
of section 7, ...) is a frozen dataclass that states what each layer needs
of it, so that no code above the model asks which class a scene is:

- the model: :meth:`SceneKind.geometry` (a :class:`analytic.geometry.Rectangle`
  and :class:`analytic.geometry.PointPairs`, the one door of the kernels),
  the reflectance image, illumination, sampling, tolerance, noise, detector;
- files and reports: :attr:`SceneKind.kind` (``meta.json``'s ``geometry``),
  :meth:`SceneKind.meta_fields`, :meth:`SceneKind.to_tables`,
  :meth:`SceneKind.describe`, :attr:`SceneKind.row_noun`,
  :attr:`SceneKind.image_key`, :meth:`SceneKind.darkness`;
- the renderer, export and the readers of other tools' files, which are
  written per kind (a Mitsuba scene, a tal capture layout, a mitransient
  film), keep a table of handlers keyed by kind name and take theirs with
  :func:`for_kind`, as Mitsuba's loader takes a plugin by its registered name.

A new kind is one module: its dataclass, decorated with
:func:`register_scene_kind` (tests/test_extension_walkthrough.py adds one).
"""

from __future__ import annotations

from typing import Any, Callable, ClassVar, Mapping, Protocol, TypeVar

from ..errors import OptionError

__all__ = ["SceneKind", "MEMBERS", "SCENE_KINDS", "register_scene_kind", "is_scene", "for_kind", "SceneKindError"]

Handler = TypeVar("Handler")


class SceneKindError(OptionError):
    """A scene of a kind that some layer (the renderer, an exporter, a reader) has no handler for."""


class SceneKind(Protocol):
    """What the model, the renderer, export, the readers and the reports need of a scene.

    Attributes
    ----------
    kind : str
        The registry's name of the kind: ``meta.json``'s ``geometry`` and the
        key of every layer's handler table.
    row_noun : str
        What one row of its transient is, singular ("sensor", "pair").
    image_key : str
        The scene-file key of its reflectance image ("plane.reflectance").
    name, pixels, reflectance, intensity, illumination, sampling, tolerance, noise, detector
        As :class:`analytic.scenes.common.Scene` has them: the image is M x M
        (``pixels``), the intensity in W/sr.
    """

    kind: ClassVar[str]
    row_noun: ClassVar[str]
    image_key: ClassVar[str]
    name: str
    pixels: int
    reflectance: Any
    intensity: float
    illumination: Any
    sampling: Any
    tolerance: float
    noise: Any
    detector: Any

    @property
    def sensor_count(self) -> int:
        """The transient's rows (sensors or pairs)."""

    @property
    def pixel_size(self) -> tuple[float, float]:
        """The image's pixel sides (du, dv) along its columns and rows, metres."""

    def geometry(self):
        """The model's rectangle and point pairs (:mod:`analytic.geometry`)."""

    def replace(self, **changes) -> "SceneKind":
        """A copy with some fields changed (validated again)."""

    def describe(self) -> str:
        """The transient's rows in words for reports ("16 sensors", "64 pairs (confocal scan of ...)")."""

    def darkness(self) -> tuple[str, str] | None:
        """(scene-file key, why) when the scene sends no light at all (a black surface), else None."""

    def meta_fields(self) -> dict:
        """The kind's own keys of ``meta.json`` (:func:`analytic.files.build_meta`); keys it has not are None."""

    def to_tables(self, shared: dict) -> dict:
        """Its scene-file tables, with ``shared`` (illumination, sampling) placed where its file puts them."""


#: Every registered kind by name.
SCENE_KINDS: dict[str, type] = {}


#: Every member the protocol asks of a kind (a class attribute, a property, a method or a dataclass field).
MEMBERS = tuple(sorted(set(SceneKind.__annotations__) | {
    name for name, value in vars(SceneKind).items() if callable(value) or isinstance(value, property)}
    - {"__init__", "__subclasshook__", "_is_protocol", "__class_getitem__", "__init_subclass__"}))


def register_scene_kind(cls: type) -> type:
    """Register a scene kind under ``cls.kind`` (a class decorator).

    Raises
    ------
    TypeError
        A class without its own ``kind`` name, or without a member of :class:`SceneKind` (named).
    ValueError
        A name registered already by another class.
    """
    name = cls.__dict__.get("kind")
    if not isinstance(name, str) or not name:
        raise TypeError(f"{cls.__name__}: a scene kind states its name as a class attribute `kind`")
    fields = getattr(cls, "__dataclass_fields__", {})
    missing = [member for member in MEMBERS if not (hasattr(cls, member) or member in fields)]
    if missing:
        raise TypeError(f"{cls.__name__}: a scene kind needs {', '.join(missing)} (analytic.scenes.kinds.SceneKind)")
    if SCENE_KINDS.get(name, cls) is not cls:
        raise ValueError(f"scene kind {name!r} is registered already ({SCENE_KINDS[name].__name__})")
    SCENE_KINDS[name] = cls
    return cls


def is_scene(value) -> bool:
    """Whether ``value`` is a scene of a registered kind.

    No kind needs importing first: an object of a kind's class exists only once the class's module ran,
    and with it its registration.
    """
    return isinstance(value, tuple(SCENE_KINDS.values()))


def for_kind(handlers: Mapping[str, Handler], scene, what: str, *,
             default: Callable | None = None) -> Handler:
    """The handler of ``scene``'s kind in ``handlers`` (keyed by kind name), else of the nearest registered
    kind it derives from, else ``default``.

    Raises
    ------
    SceneKindError
        When no handler applies and there is no default: naming the kind and ``what`` it cannot do.
    """
    for cls in type(scene).__mro__:
        name = cls.__dict__.get("kind")
        if name in handlers:
            return handlers[name]
    if default is not None:
        return default
    raise SceneKindError(f"{what}: a scene of kind {getattr(scene, 'kind', type(scene).__name__)!r} is not "
                         f"supported (supported: {', '.join(handlers)})")

