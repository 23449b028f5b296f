"""Render a scene's transient y_k[n] by Monte Carlo, in chunks, with checkpoints.

Samples are drawn in chunks of bounded memory; sample i's random numbers
depend only on (seed, i), so the result does not depend on the chunking, on
interruptions, or on resuming. Per-bin sums Σc and Σc² of the per-sample
contributions are kept in float64 (Mitsuba's own film accumulates in float32
and stalls once a pixel holds about 2^24 times a sample's value); the
estimate is Σc / S and its standard error

    se = sqrt((Σc² / S - (Σc / S)²) / (S - 1)).

With ``out_dir`` the accumulated state goes to ``render_state.npz`` and the
current estimate to ``transient.{npy,exr}``, ``stderr.npy`` and
``meta.json`` after every few seconds of work, every file atomically; Ctrl-C
or SIGTERM stops after writing what the finished chunks hold, and
``resume=True`` carries on from there.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from analytic.io import atomic_write, build_meta, write_transient
from analytic.scene import Scene
from analytic.waveforms import make_waveform

__all__ = ["RenderResult", "render", "scene_fingerprint", "standard_error", "chunk_ranges",
           "sigterm_as_interrupt", "DEFAULT_CHUNK", "STATE_FILE"]

#: Samples per chunk: one fused kernel of this width keeps memory flat
#: (only the K x N accumulators are stored) and takes well under a second.
DEFAULT_CHUNK = 2**22

STATE_FILE = "render_state.npz"

# Seconds between checkpoints: often enough that an interruption loses
# little, rarely enough that fsyncs do not slow small chunks down.
_CHECKPOINT_SECONDS = 5.0


@dataclass(frozen=True)
class RenderResult:
    """A Monte Carlo estimate of y_k[n].

    Attributes
    ----------
    mean : numpy.ndarray
        ``(K, N)`` float64 estimate of y_k[n] (units of y: W/sr-normalised,
        m⁻² · m per unit source intensity).
    stderr : numpy.ndarray
        ``(K, N)`` float64 standard error of ``mean``.
    samples : int
        Samples drawn (points on the plane; each serves every sensor).
    seed : int
        Render seed.
    variant : str
        Mitsuba variant used.
    seconds : float
        Wall time spent sampling in this call, seconds.
    """

    mean: np.ndarray
    stderr: np.ndarray
    samples: int
    seed: int
    variant: str
    seconds: float


def standard_error(sums: np.ndarray, sums_of_squares: np.ndarray, samples: int) -> np.ndarray:
    """Standard error of the mean from float64 first and second moments.

    Parameters
    ----------
    sums, sums_of_squares : numpy.ndarray
        Σc and Σc² over ``samples`` per-sample contributions.
    samples : int
        S >= 2.

    Returns
    -------
    numpy.ndarray
        sqrt(max(Σc²/S - (Σc/S)², 0) / (S - 1)); 0 where no sample landed.
    """
    if samples < 2:
        return np.full(np.shape(sums), np.inf)
    mean = sums / samples
    variance = np.maximum(sums_of_squares / samples - mean * mean, 0.0)
    return np.sqrt(variance / (samples - 1))


def scene_fingerprint(scene: Scene) -> str:
    """SHA-256 of everything in a scene that changes what the renderer computes.

    The attenuation and noise settings are left out: the renderer always
    renders physical transport, noiselessly.
    """
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    description = {
        "size": repr(float(scene.size)), "pixels": int(scene.pixels),
        "source": [repr(float(v)) for v in scene.source],
        "sensors": [[repr(float(v)) for v in p] for p in scene.sensors],
        "sampling": [repr(float(scene.sampling.bin_width_opl)), repr(float(scene.sampling.start_opl)),
                     int(scene.sampling.count)],
        "waveform": waveform.description,
    }
    digest = hashlib.sha256(json.dumps(description, sort_keys=True).encode())
    digest.update(np.ascontiguousarray(scene.reflectance, dtype=np.float64).tobytes())
    return digest.hexdigest()


def _save_state(path: Path, sums, squares, samples, seed, fingerprint, variant) -> None:
    def write(temporary):
        with open(temporary, "wb") as stream:
            np.savez(stream, sums=sums, sums_of_squares=squares, samples=np.int64(samples),
                     seed=np.int64(seed), fingerprint=np.array(fingerprint), variant=np.array(variant))
    atomic_write(path, write)


def _load_state(path: Path, seed: int, fingerprint: str, shape: tuple[int, int], variant: str):
    if not path.is_file():
        raise ValueError(f"resume: no {STATE_FILE} in {path.parent}")
    with np.load(path, allow_pickle=False) as state:
        if str(state["fingerprint"]) != fingerprint:
            raise ValueError(f"resume: {path} belongs to a different scene (fingerprint differs)")
        if int(state["seed"]) != seed:
            raise ValueError(f"resume: {path} was rendered with seed {int(state['seed'])}, not {seed}")
        # another variant computes other last bits: mixing them breaks reproducibility
        if str(state["variant"]) != variant:
            raise ValueError(f"resume: {path} was rendered with variant {state['variant']}, not {variant}")
        sums = np.array(state["sums"], dtype=np.float64)
        squares = np.array(state["sums_of_squares"], dtype=np.float64)
        samples = int(state["samples"])
    if sums.shape != shape or squares.shape != shape:
        raise ValueError(f"resume: {path} holds shape {sums.shape}, expected {shape}")
    return sums, squares, samples


def chunk_ranges(samples: int, chunk_size: int, start: int = 0) -> list[tuple[int, int]]:
    """The chunks ``(first, count)`` covering samples [start, samples).

    Every render (and every sweep task) cuts its sample range here, so equal
    chunk sizes give equal chunks. Chunks never straddle a multiple of 2^32:
    the integrator's sample index is 32-bit.
    """
    ranges, done = [], int(start)
    while done < samples:
        count = min(chunk_size, samples - done, 2**32 - done % 2**32)
        ranges.append((done, count))
        done += count
    return ranges


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


def render(scene: Scene, *, spp: int, seed: int = 0, out_dir: str | Path | None = None,
           variant: str | None = None, resume: bool = False, chunk_size: int | None = None,
           progress: bool = True, on_chunk: Callable[[int], None] | None = None) -> RenderResult:
    """Monte Carlo estimate of the scene's transient y_k[n] and its standard error.

    Parameters
    ----------
    scene : Scene
        The scene. Its ``attenuation`` is not read: the renderer renders
        physical transport (``lambertian``) only.
    spp : int
        Total samples (points on the plane; each serves all K sensors).
    seed : int
        Seed, 0 <= seed < 2^32; sample i depends on (seed, i) only.
    out_dir : str or Path, optional
        Folder for checkpoints and outputs (``render_state.npz``,
        ``transient.npy``/``.exr``, ``stderr.npy``, ``meta.json``).
    variant : str, optional
        Mitsuba variant; see :func:`transient.backend.select_variant`.
    resume : bool
        Continue from ``out_dir/render_state.npz``; refused (ValueError) if it
        belongs to another scene or seed. Samples already done count towards
        ``spp``.
    chunk_size : int, optional
        Samples per kernel launch (memory and checkpoint granularity).
        Default 2^22.
    progress : bool
        Show a tqdm progress bar over samples (on stderr).
    on_chunk : callable, optional
        Called with the number of samples done after each finished chunk has
        been added to the totals; it may raise KeyboardInterrupt to stop the
        render as Ctrl-C would (checkpoint written, exception re-raised).

    Returns
    -------
    RenderResult

    Raises
    ------
    KeyboardInterrupt
        On Ctrl-C, SIGTERM or from ``on_chunk``, after the finished chunks
        have been written to ``out_dir``.
    """
    from .backend import select_variant

    spp = int(spp)
    if spp < 2:
        raise ValueError(f"spp: need at least 2 samples for a standard error, got {spp}")
    if not 0 <= int(seed) < 2**32:
        raise ValueError(f"seed: must be in [0, 2^32), got {seed}")
    seed = int(seed)
    chunk_size = DEFAULT_CHUNK if chunk_size is None else int(chunk_size)
    if not 1 <= chunk_size <= 2**31:
        raise ValueError(f"chunk_size: must be in [1, 2^31], got {chunk_size}")
    if resume and out_dir is None:
        raise ValueError("resume: needs out_dir")

    variant = select_variant(variant)
    from .mitsuba_scene import load_scene

    loaded = load_scene(scene)
    integrator = loaded.integrator()
    shape = (scene.sensor_count, scene.sampling.count)
    fingerprint = scene_fingerprint(scene)
    out_dir = Path(out_dir) if out_dir is not None else None
    state_path = out_dir / STATE_FILE if out_dir is not None else None

    sums, squares, done = np.zeros(shape), np.zeros(shape), 0
    if resume:
        sums, squares, done = _load_state(state_path, seed, fingerprint, shape, variant)
        if done > spp:
            raise ValueError(f"resume: {state_path} already holds {done} samples, more than spp = {spp}")
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    totals = (sums, squares, done)

    def checkpoint():
        sums, squares, done = totals
        if out_dir is None or done < 2:
            return
        _save_state(state_path, sums, squares, done, seed, fingerprint, variant)
        meta = build_meta(scene, kind="render", samples=done, seed=seed, variant=variant,
                          requested_samples=spp, scene_fingerprint=fingerprint)
        write_transient(out_dir, sums / done, meta, stderr=standard_error(sums, squares, done))

    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=spp, initial=done, unit="sample", unit_scale=True, desc="render", leave=False)
    started = time.perf_counter()
    last_checkpoint = started
    try:
        with sigterm_as_interrupt():
            for first, count in chunk_ranges(spp, chunk_size, start=done):
                chunk_sums, chunk_squares = integrator.render_transient(
                    loaded, seed=seed, first_sample=first, sample_count=count)
                # One assignment: a signal between bytecodes never leaves the
                # totals half updated.
                totals = (totals[0] + chunk_sums, totals[1] + chunk_squares, first + count)
                if bar is not None:
                    bar.update(count)
                now = time.perf_counter()
                if now - last_checkpoint >= _CHECKPOINT_SECONDS:
                    checkpoint()
                    last_checkpoint = now
                if on_chunk is not None:
                    on_chunk(totals[2])
    except KeyboardInterrupt:
        checkpoint()
        raise
    finally:
        if bar is not None:
            bar.close()
    seconds = time.perf_counter() - started
    checkpoint()
    sums, squares, done = totals
    return RenderResult(mean=sums / done, stderr=standard_error(sums, squares, done), samples=done,
                        seed=seed, variant=variant, seconds=seconds)
