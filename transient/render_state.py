"""A render's saved state: the checkpoint file, the scene it belongs to, and their checks on resume.

``render_state.npz`` (:data:`STATE_FILE`) holds a render's accumulated
replica sums per unit intensity with a SHA-256 checksum of everything in
it, and the identity of the render (scene fingerprint, seed, variant,
sample plan, estimator); ``render_scene.npz`` (:data:`SCENE_FILE`) holds the
scene itself (its tables and reflectance image). Together they are all a
resume needs (:func:`read_saved_render`); a state that is missing,
unreadable, corrupted, inconsistent or of another render is refused with a
:class:`RenderStateError` saying what, where and how to fix it.
:func:`transient.render.render` writes and resumes them.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analytic.errors import UserError
from analytic.files import atomic_write
from analytic.scenes.common import Scene
from analytic.scenes.kinds import for_kind
from analytic.waveforms import make_waveform

from .chunks import ReplicaAccumulator, ReplicaLayout

__all__ = ["RenderStateError", "SavedRender", "read_saved_render", "scene_fingerprint", "save_scene",
           "state_identity", "save_state", "load_state", "STATE_FILE", "SCENE_FILE", "STATE_FORMAT"]

#: The accumulated state of a render, written with its first chunk and then every few seconds.
STATE_FILE = "render_state.npz"

#: The scene a render folder belongs to (tables and reflectance), written with its first checkpoint.
SCENE_FILE = "render_scene.npz"

#: Identifies the state's layout and the estimator that wrote it.
STATE_FORMAT = "diffuse-imaging render state 3 (replica means, per unit intensity)"

_SCENE_FORMAT = "diffuse-imaging render scene 1"

_STATE_ARRAYS = ("partial", "replica_means")


class RenderStateError(UserError, ValueError):
    """A render state that cannot be resumed (one line: what, where, how to fix)."""


def scene_fingerprint(scene: Scene, estimator: dict | None = None) -> str:
    """SHA-256 of everything in a scene (and estimator options) that changes what the renderer computes.

    Every field but ``tolerance`` (the model's quadrature accuracy),
    ``noise`` (the model's; a render is noiseless) and ``name``. A
    relay-wall capture (:class:`analytic.scenes.relay_wall.RelayWallScene`) is
    described by its scene-file tables (wall, hidden rectangle, laser,
    sensor, scan, sampling, illumination) and its hidden image.
    """
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    description = {**for_kind(_DESCRIPTIONS, scene, "render", default=_tables_description)(scene),
                   "waveform": waveform.description, "estimator": _estimator_record(estimator)}
    digest = hashlib.sha256(json.dumps(description, sort_keys=True, default=_python_number).encode())
    digest.update(np.ascontiguousarray(scene.reflectance, dtype=np.float64).tobytes())
    return digest.hexdigest()


def _tables_description(scene) -> dict:
    """What the renderer reads of any scene kind: its kind and scene-file tables (:func:`_renderer_tables`)."""
    return {"geometry": scene.kind, "tables": _renderer_tables(scene)}


def _plane_description(scene) -> dict:
    """A plane's fields as render states have always recorded them (so that earlier renders still resume)."""
    return {
        "size": repr(float(scene.size)), "pixels": int(scene.pixels),
        "source": [repr(float(v)) for v in scene.source],
        "intensity": repr(float(scene.intensity)),
        "sensors": [[repr(float(v)) for v in p] for p in scene.sensors],
        "sampling": [repr(float(scene.sampling.bin_width_opl)), repr(float(scene.sampling.start_opl)),
                     int(scene.sampling.count)],
        "attenuation": scene.attenuation,
    }


#: A kind's own description in the fingerprint; every other kind is described by :func:`_tables_description`.
_DESCRIPTIONS = {"plane": _plane_description}


#: Scene-file keys the renderer does not read: (table, key); a whole table when key is None.
_MODEL_ONLY = (("name", None), ("noise", None), ("model", "tolerance"))


def _renderer_tables(scene) -> dict:
    """The scene's tables without what only the model reads (name, noise, tolerance) and without its image
    (a reflectance key holds the constant, or the image's place: the image itself is hashed apart)."""
    from analytic.scenes.scene_file import scene_to_tables

    tables = scene_to_tables(scene)
    for table, key in _MODEL_ONLY:
        if key is None:
            tables.pop(table, None)
        elif isinstance(tables.get(table), dict):
            tables[table].pop(key, None)
    image_table = tables[_image_table_of(scene)]
    if isinstance(image_table.get("reflectance"), np.ndarray):
        image_table["reflectance"] = "image"
    return tables


def _image_table_of(scene) -> str:
    """The table of ``scene``'s tables that holds its reflectance image (its kind's ``image_key``)."""
    return scene.image_key.split(".")[0]


def _image_table(tables: dict) -> str:
    """The table whose ``reflectance`` is the image: ``hidden`` of a relay-wall capture, else ``plane``."""
    return "hidden" if "relay_wall" in tables else "plane"


def _estimator_record(estimator: dict | None) -> dict:
    return {str(k): str(v) for k, v in sorted((estimator or {}).items())}


# -- the scene a folder belongs to ---------------------------------------------------


def save_scene(folder: Path, scene: Scene) -> None:
    """Write ``render_scene.npz``: the scene's tables (JSON) and its reflectance image, atomically."""
    from analytic.scenes.scene_file import scene_to_tables

    tables = scene_to_tables(scene)
    image = _image_table_of(scene)
    tables[image] = {key: value for key, value in tables[image].items() if key != "reflectance"}
    # JSON writes a float's repr: the scene reads back bit for bit.
    text = json.dumps(tables, sort_keys=True, allow_nan=False, default=_python_number)

    def write(temporary):
        with open(temporary, "wb") as stream:
            np.savez(stream, format=np.array(_SCENE_FORMAT), tables=np.array(text),
                     reflectance=np.ascontiguousarray(scene.reflectance, dtype=np.float64))
    atomic_write(folder / SCENE_FILE, write)


def _python_number(value):
    """A NumPy scalar as the Python number JSON can write."""
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not a number: {type(value).__name__}")


def _load_saved_scene(folder: Path) -> Scene:
    """The scene of ``render_scene.npz``; :class:`RenderStateError` when it cannot be read."""
    from analytic.scenes.scene_file import scene_from_dict

    path = folder / SCENE_FILE
    fix = f"give the scene file again: diffuse-imaging render SCENE --resume {folder}"
    if not path.is_file():
        raise RenderStateError(f"resume: no {SCENE_FILE} in {folder} (a render state without its scene); {fix}")
    try:
        with open(path, "rb") as stream, np.load(stream, allow_pickle=False) as saved:
            if str(saved["format"]) != _SCENE_FORMAT:
                raise ValueError("written by another version of the renderer")
            tables = json.loads(str(saved["tables"]))
            tables[_image_table(tables)]["reflectance"] = np.array(saved["reflectance"], dtype=np.float64)
        return scene_from_dict(tables, folder)
    except (OSError, ValueError, KeyError, TypeError, AttributeError, EOFError, zipfile.BadZipFile,
            UserError) as error:
        reason = " ".join(str(error).split()) or type(error).__name__
        raise RenderStateError(f"resume: {path} is not a readable render scene ({reason[:120]}); {fix}") \
            from None


# -- the state file ------------------------------------------------------------------


def state_identity(fingerprint: str, seed: int, variant: str, layout: ReplicaLayout, requested: int,
                   estimator: dict) -> dict:
    """What a render is: the state's identity, compared on resume and covered by its checksum."""
    return {"format": STATE_FORMAT, "fingerprint": fingerprint, "seed": int(seed), "variant": variant,
            "replicas": int(layout.replicas), "replica_size": int(layout.size), "requested": int(requested),
            "estimator": _estimator_record(estimator)}


def _checksum(identity: dict, progress: dict) -> str:
    digest = hashlib.sha256(json.dumps(identity, sort_keys=True).encode())
    digest.update(json.dumps({"done": int(progress["done"]), "completed": int(progress["completed"])}).encode())
    for name in _STATE_ARRAYS:
        array = np.ascontiguousarray(progress[name], dtype="<f8")
        digest.update(json.dumps(list(array.shape)).encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def save_state(path: Path, identity: dict, accumulator: ReplicaAccumulator) -> None:
    """Write the accumulator's state with its identity and checksum to ``path``, atomically."""
    progress = accumulator.state()

    def write(temporary):
        with open(temporary, "wb") as stream:
            np.savez(stream, identity=np.array(json.dumps(identity, sort_keys=True)),
                     done=np.int64(progress["done"]), completed=np.int64(progress["completed"]),
                     checksum=np.array(_checksum(identity, progress)),
                     **{name: progress[name] for name in _STATE_ARRAYS})
    atomic_write(path, write)


_FRESH = "delete it and render again without --resume (or into a new --out)"


def _read_state(out_dir: Path) -> tuple[dict, dict]:
    """(identity, progress) of ``out_dir``'s state, read and verified by its checksum."""
    path = out_dir / STATE_FILE
    if not out_dir.is_dir():
        raise RenderStateError(f"resume: folder {out_dir} does not exist; give the folder of the render to "
                               f"resume, or render without --resume")
    if not path.is_file():
        raise RenderStateError(f"resume: no {STATE_FILE} in {out_dir}: nothing to resume; "
                               f"render without --resume")
    stored = progress = checksum = None
    try:
        # Open the file here: np.load leaks its own handle on a file that is not an archive.
        with open(path, "rb") as stream:
            saved = np.load(stream, allow_pickle=False)
            if not isinstance(saved, np.lib.npyio.NpzFile):
                raise ValueError("a single array, not an archive")
            with saved:
                stored = json.loads(str(saved["identity"]))
                if isinstance(stored, dict) and stored.get("format") == STATE_FORMAT:
                    progress = {"done": int(saved["done"]), "completed": int(saved["completed"]),
                                **{name: np.array(saved[name], dtype=np.float64) for name in _STATE_ARRAYS}}
                    checksum = str(saved["checksum"])
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile) as error:
        reason = " ".join(str(error).split()) or type(error).__name__
        raise RenderStateError(f"resume: {path} is not a readable render state ({reason[:120]}); {_FRESH}") \
            from None
    if progress is None:
        raise RenderStateError(f"resume: {path} was written by another version of the renderer; {_FRESH}")
    try:
        intact = checksum == _checksum(stored, progress)
    except (TypeError, ValueError, KeyError):
        intact = False
    if not intact:
        raise RenderStateError(f"resume: {path} is corrupted (its checksum does not match its contents); "
                               f"{_FRESH}")
    return stored, progress


def _mismatches(stored: dict, identity: dict) -> list[str]:
    """Each argument given for a resume that differs from the state's, as "FLAG given differs from ..."."""
    found = [f"{flag} {identity[key]} differs from the state's {stored.get(key)}"
             for key, flag in (("requested", "--spp"), ("seed", "--seed"), ("variant", "--variant"))
             if stored.get(key) != identity[key]]
    if stored.get("requested") == identity["requested"] and stored.get("replicas") != identity["replicas"]:
        found.append(f"replicas {identity['replicas']} differ from the state's {stored.get('replicas')}")
    if stored.get("estimator") != identity["estimator"]:
        found.append(f"estimator options {identity['estimator']} differ from the state's "
                     f"{stored.get('estimator')}")
    elif stored.get("fingerprint") != identity["fingerprint"]:
        found.append(f"the scene given differs from the one the render was started with, saved in {SCENE_FILE}")
    return found


def load_state(out_dir: Path, identity: dict, layout: ReplicaLayout, shape) -> ReplicaAccumulator:
    """The accumulator saved in ``out_dir``, after every check; :class:`RenderStateError` otherwise."""
    stored, progress = _read_state(out_dir)
    mismatches = _mismatches(stored, identity)
    if mismatches:
        raise RenderStateError(f"resume: {'; '.join(mismatches)} (in {out_dir / STATE_FILE}); leave them out "
                               f"to resume with the state's own (diffuse-imaging render --resume {out_dir}), "
                               f"or render into a new --out")
    try:
        return ReplicaAccumulator.from_state(layout, shape, progress)
    except ValueError as error:
        raise RenderStateError(f"resume: {out_dir / STATE_FILE} holds an inconsistent state ({error}); "
                               f"{_FRESH}") from None


@dataclass(frozen=True)
class SavedRender:
    """What a render folder holds: everything :func:`resume` needs.

    Attributes
    ----------
    folder : Path
    scene : Scene
        The scene the render was started with (from ``render_scene.npz``),
        or the one given to :func:`read_saved_render`.
    spp, seed : int
        The sample count asked for and the seed.
    variant : str
        The Mitsuba variant it ran on.
    replicas : int
        R.
    estimator : dict
        ``transient_opl`` options (``strategy``, ``sampler``), as strings.
    done, planned : int
        Samples done, and R n.
    """

    folder: Path
    scene: Scene
    spp: int
    seed: int
    variant: str
    replicas: int
    estimator: dict
    done: int
    planned: int


#: How a refused resume names a scene kind.
_KIND_NAMES = {"relay_wall": "a relay-wall capture", "plane": "a plane scene"}


def _scene_differences(started: Scene, given: Scene) -> list[str]:
    """The scene keys ("[sampling] start", ...) in which ``given`` differs from the scene a render was
    started with, among those the renderer reads (not its name, noise or tolerance)."""
    old, new = _renderer_tables(started), _renderer_tables(given)
    if started.kind != given.kind:
        def named(kind):
            return _KIND_NAMES.get(kind, f"a {kind} scene")
        return [f"its kind ({named(given.kind)}; the state's: {named(started.kind)})"]
    image = _image_table_of(started)
    found = []
    for table in sorted(set(old) | set(new)):
        first, second = old.get(table, {}), new.get(table, {})
        for key in sorted(set(first) | set(second)):
            first_value, second_value = first.get(key), second.get(key)
            if (table, key) == (image, "reflectance"):
                same = np.array_equal(started.reflectance, given.reflectance)
                # a constant as itself, an image by its shape
                first_value = started.reflectance if first_value == "image" else first_value
                second_value = given.reflectance if second_value == "image" else second_value
            else:
                same = first_value == second_value
            if not same:
                found.append(f"[{table}] {key} {_shown(second_value)} (the state's: {_shown(first_value)})")
    return found


def _shown(value) -> str:
    """A scene value, short: an image by its shape, a list of points by their count."""
    if isinstance(value, np.ndarray):
        return f"a {value.shape[0]} x {value.shape[1]} image"
    if isinstance(value, list) and len(value) > 2 and all(isinstance(item, list) for item in value):
        return f"{len(value)} points"
    return "absent" if value is None else json.dumps(value, default=_python_number)


def _given_scene_mismatch(folder: Path, given: Scene, stored: dict, estimator: dict) -> str | None:
    """What differs between a scene given for a resume and the state's (None when it is the state's)."""
    if scene_fingerprint(given, estimator) == stored.get("fingerprint"):
        return None
    try:
        started = _load_saved_scene(folder)
    except RenderStateError:
        started = None
    differences = (_scene_differences(started, given)
                   if started is not None and scene_fingerprint(started, estimator) == stored.get("fingerprint")
                   else [])
    if not differences:
        return f"the scene given differs from the one the render was started with, saved in {SCENE_FILE}"
    return f"the scene given differs from the one the render was started with in {', '.join(differences)}"


def _argument_mismatches(stored: dict, *, spp: int | None, seed: int | None, variant: str | None) -> list[str]:
    """Each of --spp, --seed, --variant given again for a resume that differs from the state's."""
    given = {"requested": spp, "seed": seed, "variant": variant}
    return [f"{flag} {given[key]} differs from the state's {stored.get(key)}"
            for key, flag in (("requested", "--spp"), ("seed", "--seed"), ("variant", "--variant"))
            if given[key] is not None and given[key] != stored.get(key)]


def read_saved_render(out_dir: str | Path, *, scene: Scene | None = None, spp: int | None = None,
                      seed: int | None = None, variant: str | None = None) -> SavedRender:
    """The render saved in a folder, read and checked (state, checksum, scene, and what is given again).

    Parameters
    ----------
    out_dir : str or Path
        The render's folder.
    scene : Scene, optional
        The scene given again: it must be the state's (by its fingerprint:
        its name, noise and tolerance may differ), and is used instead of
        ``render_scene.npz`` (which may then be missing or damaged).
    spp, seed : int, optional
        Given again: each must be the state's (the sample count asked for,
        the seed).
    variant : str, optional
        Given again: must be the state's Mitsuba variant.

    Raises
    ------
    RenderStateError
        No folder, no state, an unreadable, corrupted or foreign state;
        (no scene given) a saved scene that cannot be read or does not
        match the state; or anything given again that differs from the
        state's, each named on the one line (a scene by its keys that
        differ, when the saved scene can be read).
    """
    folder = Path(out_dir)
    stored, progress = _read_state(folder)
    try:
        requested, saved_seed, saved_variant = int(stored["requested"]), int(stored["seed"]), str(stored["variant"])
        replicas, size = int(stored["replicas"]), int(stored["replica_size"])
        estimator = dict(stored["estimator"])
    except (KeyError, TypeError, ValueError) as error:
        raise RenderStateError(f"resume: {folder / STATE_FILE} lacks {error}; {_FRESH}") from None
    mismatches = _argument_mismatches(stored, spp=spp, seed=seed, variant=variant)
    if scene is not None:
        differs = _given_scene_mismatch(folder, scene, stored, estimator)
        mismatches += [differs] if differs is not None else []
    if mismatches:
        raise RenderStateError(f"resume: {'; '.join(mismatches)} (in {folder / STATE_FILE}); leave them out "
                               f"to resume with the state's own (diffuse-imaging render --resume {folder}), "
                               f"or render into a new --out")
    if scene is None:
        scene = _load_saved_scene(folder)
        if scene_fingerprint(scene, estimator) != stored.get("fingerprint"):
            raise RenderStateError(f"resume: {folder / SCENE_FILE} does not hold the scene of "
                                   f"{folder / STATE_FILE}; give the scene file again: diffuse-imaging render "
                                   f"SCENE --resume {folder}")
    return SavedRender(folder=folder, scene=scene, spp=requested, seed=saved_seed, variant=saved_variant,
                       replicas=replicas, estimator=estimator, done=int(progress["done"]),
                       planned=replicas * size)
