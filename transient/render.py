"""Render a scene's transient y_k[n] by Monte Carlo, in chunks, with verified checkpoints.

A render of ``spp`` samples is R replicas of n = ⌈spp / R⌉ samples
(:mod:`transient.chunks`): each replica a complete stratified estimate of
y, independent of the others. The estimate is the mean of the replica
means and its standard error their spread over sqrt(R), with R - 1 degrees
of freedom (compare with ``validation.compare.compare_transients(...,
dof=result.dof)``). Sample g's random numbers depend only on (seed, g), so
the result does not depend on the chunking, on interruptions or on
resuming (up to the rounding of float64 additions).

With ``out_dir`` the accumulated state goes to ``render_state.npz`` as soon
as the first chunk is done and then every 5 seconds, and the current
estimate (the complete replicas) to ``transient.{npy,exr}``, ``stderr.npy``
and ``meta.json`` once two replicas are complete; every file is written
atomically. The state carries a SHA-256 checksum of everything in it;
``resume=True`` refuses a state that is missing, unreadable, corrupted,
inconsistent or from another scene, seed, variant or sample plan, with a
:class:`RenderStateError` saying what, where and how to fix it. Ctrl-C,
SIGTERM and ``kill -9`` lose at most the work since the last checkpoint.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import signal
import threading
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from analytic.errors import UserError
from analytic.io import atomic_write, build_meta, write_transient
from analytic.scene import Scene
from analytic.waveforms import make_waveform
from analytic.window import window_share

from .chunks import MAX_SAMPLES, Chunk, ReplicaAccumulator, ReplicaLayout

__all__ = ["RenderResult", "RenderStateError", "render", "render_loaded", "scene_fingerprint", "sigterm_as_interrupt",
           "DEFAULT_CHUNK", "DEFAULT_CHUNK_GPU", "FIRST_CHUNK", "STATE_FILE", "STATE_FORMAT", "MAX_SAMPLES"]

#: Largest chunk on a CPU, samples: one fused kernel of this width keeps
#: memory flat (only the per-replica K x N sums are stored) and takes well
#: under a second.
DEFAULT_CHUNK = 2**22

#: Largest chunk on a GPU: tracing a chunk's kernel costs 1.5 to 5 ms of
#: Python with an impulse (up to 0.1 s for a Butterworth pulse and 64
#: sensors, measured on a CPU), which 2^22 samples at 1e10 samples/s would
#: not amortise.
DEFAULT_CHUNK_GPU = 2**28

#: The first chunk: small, so that the first checkpoint comes within a
#: second; chunks then double up to the chunk size.
FIRST_CHUNK = 2**16

STATE_FILE = "render_state.npz"

#: Identifies the state's layout and the estimator that wrote it.
STATE_FORMAT = "diffuse-imaging render state 2 (stratified replicas)"

# Seconds between checkpoints: often enough that an interruption loses
# little, rarely enough that fsyncs do not slow small chunks down.
_CHECKPOINT_SECONDS = 5.0

_STATE_ARRAYS = ("partial", "replica_mean", "deviations")


class RenderStateError(UserError, ValueError):
    """A render state that cannot be resumed (one line: what, where, how to fix)."""


@dataclass(frozen=True)
class RenderResult:
    """A Monte Carlo estimate of y_k[n].

    Attributes
    ----------
    mean : numpy.ndarray
        ``(K, N)`` float64 estimate of y_k[n] (units of y: m⁻² · m per unit
        source intensity).
    stderr : numpy.ndarray
        ``(K, N)`` float64 standard error of ``mean``, from the replicas.
    samples : int
        Samples drawn, R n (points on the plane; each serves every sensor).
    seed : int
        Render seed.
    variant : str
        Mitsuba variant used.
    seconds : float
        Wall time spent sampling in this call, seconds.
    replicas : int
        R, independent replicas of n samples each.
    dof : int
        Degrees of freedom of ``stderr``: R - 1.
    """

    mean: np.ndarray
    stderr: np.ndarray
    samples: int
    seed: int
    variant: str
    seconds: float
    replicas: int
    dof: int


def scene_fingerprint(scene: Scene, estimator: dict | None = None) -> str:
    """SHA-256 of everything in a scene (and estimator options) that changes what the renderer computes.

    The attenuation and noise settings are left out: the renderer always
    renders physical transport, noiselessly.
    """
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    description = {
        "size": repr(float(scene.size)), "pixels": int(scene.pixels),
        "source": [repr(float(v)) for v in scene.source],
        "intensity": repr(float(scene.intensity)),
        "sensors": [[repr(float(v)) for v in p] for p in scene.sensors],
        "sampling": [repr(float(scene.sampling.bin_width_opl)), repr(float(scene.sampling.start_opl)),
                     int(scene.sampling.count)],
        "waveform": waveform.description,
        "estimator": {str(k): str(v) for k, v in sorted((estimator or {}).items())},
    }
    digest = hashlib.sha256(json.dumps(description, sort_keys=True).encode())
    digest.update(np.ascontiguousarray(scene.reflectance, dtype=np.float64).tobytes())
    return digest.hexdigest()


# -- the state file ------------------------------------------------------------------


def _identity(fingerprint: str, seed: int, variant: str, layout: ReplicaLayout, requested: int) -> dict:
    return {"format": STATE_FORMAT, "fingerprint": fingerprint, "seed": int(seed), "variant": variant,
            "replicas": int(layout.replicas), "replica_size": int(layout.size), "requested": int(requested)}


def _checksum(identity: dict, progress: dict) -> str:
    digest = hashlib.sha256(json.dumps(identity, sort_keys=True).encode())
    digest.update(json.dumps({"done": int(progress["done"]), "completed": int(progress["completed"])}).encode())
    for name in _STATE_ARRAYS:
        digest.update(np.ascontiguousarray(progress[name], dtype="<f8").tobytes())
    return digest.hexdigest()


def _save_state(path: Path, identity: dict, accumulator: ReplicaAccumulator) -> None:
    progress = accumulator.state()

    def write(temporary):
        with open(temporary, "wb") as stream:
            np.savez(stream, identity=np.array(json.dumps(identity, sort_keys=True)),
                     done=np.int64(progress["done"]), completed=np.int64(progress["completed"]),
                     checksum=np.array(_checksum(identity, progress)),
                     **{name: progress[name] for name in _STATE_ARRAYS})
    atomic_write(path, write)


def _load_state(out_dir: Path, identity: dict, layout: ReplicaLayout, shape) -> ReplicaAccumulator:
    """The accumulator saved in ``out_dir``, after every check; :class:`RenderStateError` otherwise."""
    path = out_dir / STATE_FILE
    fresh = "delete it and render again without --resume (or into a new --out)"
    if not out_dir.is_dir():
        raise RenderStateError(f"resume: folder {out_dir} does not exist; give the folder of the render to "
                               f"resume, or render without --resume")
    if not path.is_file():
        raise RenderStateError(f"resume: no {STATE_FILE} in {out_dir}: nothing to resume; "
                               f"render without --resume")
    try:
        # Open the file here: np.load leaks its own handle on a file that is not an archive.
        with open(path, "rb") as stream:
            saved = np.load(stream, allow_pickle=False)
            if not isinstance(saved, np.lib.npyio.NpzFile):
                raise ValueError("a single array, not an archive")
            with saved:
                stored = json.loads(str(saved["identity"]))
                progress = {"done": int(saved["done"]), "completed": int(saved["completed"]),
                            **{name: np.array(saved[name], dtype=np.float64) for name in _STATE_ARRAYS}}
                checksum = str(saved["checksum"])
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile) as error:
        reason = " ".join(str(error).split()) or type(error).__name__
        raise RenderStateError(f"resume: {path} is not a readable render state ({reason[:120]}); {fresh}") \
            from None
    if not isinstance(stored, dict) or stored.get("format") != STATE_FORMAT:
        raise RenderStateError(f"resume: {path} was written by another version of the renderer; {fresh}")
    try:
        intact = checksum == _checksum(stored, progress)
    except (TypeError, ValueError):
        intact = False
    if not intact:
        raise RenderStateError(f"resume: {path} is corrupted (its checksum does not match its contents); "
                               f"{fresh}")
    if stored.get("fingerprint") != identity["fingerprint"]:
        raise RenderStateError(f"resume: {path} belongs to a different scene or estimator; resume with the "
                               f"scene it was rendered from, or render into a new --out")
    for key, flag in (("seed", "--seed"), ("variant", "--variant")):
        if stored.get(key) != identity[key]:
            raise RenderStateError(f"resume: {path} was rendered with {key} {stored.get(key)}, not "
                                   f"{identity[key]}; pass {flag} {stored.get(key)} or render into a new --out")
    planned = (stored.get("replicas"), stored.get("replica_size"))
    if planned != (identity["replicas"], identity["replica_size"]):
        requested = stored.get("requested")
        if isinstance(requested, int) and identity["requested"] < progress["done"]:
            raise RenderStateError(f"resume: spp = {identity['requested']} is below the {progress['done']} "
                                   f"samples already done in {path}; resume with --spp {requested}")
        raise RenderStateError(f"resume: {path} was planned for spp = {requested} ({planned[0]} replicas of "
                               f"{planned[1]}); resume with --spp {requested}, or render into a new --out")
    try:
        return ReplicaAccumulator.from_state(layout, shape, progress)
    except ValueError as error:
        raise RenderStateError(f"resume: {path} holds an inconsistent state ({error}); {fresh}") from None


@contextlib.contextmanager
def sigterm_as_interrupt():
    """Turn SIGTERM into KeyboardInterrupt (main thread only), so both keep finished work."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")
    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _chunks(start: int, end: int, largest: int):
    """Chunks (first, count) covering [start, end): from :data:`FIRST_CHUNK` doubling up to ``largest``."""
    size, first, index = min(FIRST_CHUNK, largest), start, 0
    while first < end:
        count = min(size, end - first)
        yield Chunk(index, first, count)
        first, index, size = first + count, index + 1, min(2 * size, largest)


def render_loaded(loaded, *, spp: int, seed: int = 0, replicas: int | None = None,
                  chunk_size: int | None = None) -> RenderResult:
    """Render an already loaded Mitsuba scene of one of our integrators (no files, no resume).

    For scenes that are not an :class:`analytic.scene.Scene` (the corner of
    ``transient.mitsuba_scene.corner_scene_dict``), rendered with the same
    replicas and chunks as :func:`render`.

    Parameters
    ----------
    loaded : mitsuba.Scene
        Loaded with ``transient_opl`` or ``transient_opl_path``.
    spp, seed, replicas, chunk_size
        As for :func:`render`.
    """
    import mitsuba as mi

    if chunk_size is None:
        chunk_size = DEFAULT_CHUNK_GPU if mi.variant().startswith("cuda") else DEFAULT_CHUNK
    _check_arguments(spp, seed, chunk_size, replicas)
    layout = ReplicaLayout.for_samples(int(spp), replicas)
    integrator = loaded.integrator()
    shape = (len(loaded.sensors()), int(integrator.bins))
    accumulator = ReplicaAccumulator(layout, shape)
    started = time.perf_counter()
    for chunk in _chunks(0, layout.samples, int(chunk_size)):
        accumulator.add(chunk, integrator.render_chunk(loaded, seed=int(seed), layout=layout, first=chunk.first,
                                                       count=chunk.count))
    return RenderResult(mean=accumulator.mean(), stderr=accumulator.stderr(), samples=accumulator.samples,
                        seed=int(seed), variant=mi.variant(), seconds=time.perf_counter() - started,
                        replicas=accumulator.completed, dof=accumulator.dof)


def _check_arguments(spp, seed, chunk_size, replicas):
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)):
        raise ValueError(f"spp: must be an integer, got {spp!r}")
    if not 2 <= spp <= MAX_SAMPLES:
        raise ValueError(f"spp: must be in [2, 2^48] (2^48 samples take about 108 days at 3e7 samples/s on "
                         f"2 CPU cores, 4 hours at 2e10 samples/s on a GPU), got {spp}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise ValueError(f"seed: must be an integer in [0, 2^32), got {seed!r}")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) \
            or not 1 <= chunk_size <= 2**31:
        raise ValueError(f"chunk_size: must be an integer in [1, 2^31], got {chunk_size!r}")
    if replicas is not None and (isinstance(replicas, bool) or not isinstance(replicas, (int, np.integer))
                                 or not 2 <= replicas <= spp):
        raise ValueError(f"replicas: must be an integer in [2, spp = {spp}], got {replicas!r}")


def render(scene: Scene, *, spp: int, seed: int = 0, out_dir: str | Path | None = None,
           variant: str | None = None, resume: bool = False, chunk_size: int | None = None,
           progress: bool = True, on_chunk: Callable[[int], None] | None = None,
           replicas: int | None = None, estimator: dict | None = None) -> RenderResult:
    """Monte Carlo estimate of the scene's transient y_k[n] and its standard error.

    Parameters
    ----------
    scene : Scene
        The scene. Its ``attenuation`` is not read: the renderer renders
        physical transport (``lambertian``) only.
    spp : int
        Samples (points on the plane; each serves all K sensors),
        2 <= spp <= 2^48. The render draws R ⌈spp / R⌉, up to R - 1 more.
    seed : int
        Seed, 0 <= seed < 2^32; sample g depends on (seed, g) only.
    out_dir : str or Path, optional
        Folder for checkpoints and outputs (``render_state.npz``,
        ``transient.npy``/``.exr``, ``stderr.npy``, ``meta.json``).
    variant : str, optional
        Mitsuba variant; see :func:`transient.backend.select_variant`.
    resume : bool
        Continue from ``out_dir/render_state.npz`` (same scene, seed,
        variant, ``spp`` and ``replicas``); :class:`RenderStateError` if it
        cannot.
    chunk_size : int, optional
        Most samples per kernel launch (memory and checkpoint granularity),
        1 <= chunk_size <= 2^31. Default :data:`DEFAULT_CHUNK` (2^22) on a
        CPU, :data:`DEFAULT_CHUNK_GPU` (2^28) on a CUDA variant.
    progress : bool
        Show a tqdm progress bar over samples (on stderr).
    on_chunk : callable, optional
        Called with the number of samples done after each finished chunk has
        been added to the totals; it may raise KeyboardInterrupt to stop the
        render as Ctrl-C would (checkpoint written, exception re-raised).
    replicas : int, optional
        R (default :data:`transient.chunks.DEFAULT_REPLICAS`).
    estimator : dict, optional
        ``transient_opl`` options (``strategy``, ``sampler``), for
        measurements; part of the scene's fingerprint.

    Returns
    -------
    RenderResult

    Raises
    ------
    ValueError
        A bad argument, before any work.
    RenderStateError
        ``resume`` and a state that cannot be resumed.
    transient.backend.BackendError
        The variant cannot run here (no CUDA device, old libLLVM).
    KeyboardInterrupt
        On Ctrl-C, SIGTERM or from ``on_chunk``, after the finished chunks
        have been written to ``out_dir``.
    """
    gpu = variant is not None and str(variant).startswith("cuda")
    chunk_size = (DEFAULT_CHUNK_GPU if gpu else DEFAULT_CHUNK) if chunk_size is None else chunk_size
    _check_arguments(spp, seed, chunk_size, replicas)
    spp, seed, chunk_size = int(spp), int(seed), int(chunk_size)
    if resume and out_dir is None:
        raise ValueError("resume: needs out_dir")
    layout = ReplicaLayout.for_samples(spp, replicas)
    estimator = dict(estimator or {})

    from .backend import select_variant

    variant = select_variant(variant)
    shape = (scene.sensor_count, scene.sampling.count)
    fingerprint = scene_fingerprint(scene, estimator)
    identity = _identity(fingerprint, seed, variant, layout, spp)
    out_dir = Path(out_dir) if out_dir is not None else None
    accumulator = (_load_state(out_dir, identity, layout, shape) if resume
                   else ReplicaAccumulator(layout, shape))

    from .mitsuba_scene import load_scene

    loaded = load_scene(scene, **estimator)
    integrator = loaded.integrator()
    share = window_share(scene) if out_dir is not None else None

    def checkpoint():
        if out_dir is None:
            return
        _save_state(out_dir / STATE_FILE, identity, accumulator)
        if accumulator.completed < 2:
            return
        meta = build_meta(scene, kind="render", samples=int(accumulator.samples), seed=seed,
                          window_share=share, variant=variant, requested_samples=spp,
                          scene_fingerprint=fingerprint, replicas=int(accumulator.completed),
                          dof=int(accumulator.dof))
        write_transient(out_dir, accumulator.mean(), meta, stderr=accumulator.stderr())

    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=layout.samples, initial=accumulator.done, unit="sample", unit_scale=True,
                   desc="render", leave=False)
    started = time.perf_counter()
    last_checkpoint = None
    try:
        with sigterm_as_interrupt():
            for chunk in _chunks(accumulator.done, layout.samples, chunk_size):
                sums = integrator.render_chunk(loaded, seed=seed, layout=layout, first=chunk.first,
                                               count=chunk.count)
                accumulator.add(chunk, sums)
                if bar is not None:
                    bar.update(chunk.count)
                now = time.perf_counter()
                # The first chunk (small) is checkpointed at once; then every few seconds.
                if last_checkpoint is None or now - last_checkpoint >= _CHECKPOINT_SECONDS:
                    checkpoint()
                    last_checkpoint = time.perf_counter()
                if on_chunk is not None:
                    on_chunk(accumulator.done)
    except KeyboardInterrupt:
        checkpoint()
        raise
    finally:
        if bar is not None:
            bar.close()
    seconds = time.perf_counter() - started
    checkpoint()
    return RenderResult(mean=accumulator.mean(), stderr=accumulator.stderr(), samples=accumulator.samples,
                        seed=seed, variant=variant, seconds=seconds, replicas=accumulator.completed,
                        dof=accumulator.dof)
