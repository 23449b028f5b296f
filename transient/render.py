"""Render a scene's transient y_k[n] by Monte Carlo, in chunks, with verified checkpoints.

A render of ``spp`` samples is R replicas of n = ⌈spp / R⌉ samples
(:mod:`transient.chunks`): each replica a complete stratified estimate of
y, independent of the others. The estimate is the mean of the replica
means and its standard error their spread over sqrt(R), with R - 1 degrees
of freedom (compare with ``validation.judging.compare.compare_transients(...,
dof=result.dof)``). Sample g's random numbers depend only on (seed, g), so
the result does not depend on the chunking, on interruptions or on
resuming (up to the rounding of float64 additions). The replicas are
rendered per unit source intensity and multiplied by I (float64) once at
the end, so y(I) / I is the same for every I to one rounding.

With ``out_dir`` the folder holds, every file written atomically:

- ``render_state.npz``: the accumulated state, as soon as the first chunk
  is done and then every 5 seconds, with a SHA-256 checksum of everything
  in it, and ``render_scene.npz``: the scene itself (its tables and
  reflectance image). Together they are all a resume needs:
  :func:`resume` (``diffuse-imaging render --resume DIR``) takes the scene,
  seed, sample count, replicas, estimator and variant from them, and
  refuses, naming each, any that is given again differently.
- ``partial/``: while the render runs (and after an interruption), the
  estimate of the complete replicas (once two are): ``transient.{npy,exr,h5}``,
  ``stderr.npy``, ``replicas.npy`` and ``meta.json`` with
  ``"complete": false``.
- ``transient.{npy,exr,h5}``, ``stderr.npy``, ``replicas.npy`` (the R
  replica means, ``(R, K, N)``, whose mean is ``transient.npy``) and
  ``meta.json`` with ``"complete": true``: only when every replica is done;
  ``partial/`` is then removed. A new render's first checkpoint removes an
  earlier render's complete files (and its figure, :data:`FIGURE_FILE`)
  from the folder together with replacing its state, so complete-looking
  files are always those of the folder's own state.

``resume=True`` refuses a state that is missing, unreadable, corrupted,
inconsistent or from another scene, seed, variant or sample plan, with a
:class:`~transient.render_state.RenderStateError` saying what, where and
how to fix it (:mod:`transient.render_state` reads and checks the state).
Ctrl-C, SIGTERM and ``kill -9`` lose at most the work since the last checkpoint;
Ctrl-C and SIGTERM end in :class:`RenderInterrupted`, which says how far
the render got.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from analytic.errors import OptionError
from analytic.files import build_meta, discard, save_npy, staged_writes, write_transient
from analytic.resources import require_memory
from analytic.scenes.common import Scene
from analytic.scenes.kinds import for_kind
from analytic.operator.window import window_share

from .chunks import MAX_SAMPLES, Chunk, ReplicaAccumulator, ReplicaLayout, render_memory_bytes
from .render_state import (STATE_FILE, load_state, read_saved_render, save_scene, save_state, scene_fingerprint,
                           state_identity)

__all__ = ["RenderResult", "RenderInterrupted", "render", "resume", "render_loaded", "sigterm_as_interrupt",
           "DEFAULT_CHUNK", "DEFAULT_CHUNK_GPU", "FIRST_CHUNK", "CHUNK_ROWS", "default_chunk", "PARTIAL_FOLDER", "REPLICAS_FILE", "FIGURE_FILE",
           "MAX_SAMPLES"]

#: Largest chunk on a CPU, samples: one fused kernel of this width keeps
#: memory flat (only the per-replica K x N sums are stored) and takes well
#: under a second.
DEFAULT_CHUNK = 2**22

#: Largest chunk on a GPU: tracing a chunk's kernel costs milliseconds of
#: Python, which a GPU's chunk of 2^22 samples would not amortise; chunks
#: of 2^30 ran faster than 2^28 there and still take a fraction of a second
#: (docs/benchmarks.md, "The renderer on a GPU").
DEFAULT_CHUNK_GPU = 2**30

#: The first chunk: small, so that the first checkpoint comes within a
#: second; chunks then double up to the chunk size.
FIRST_CHUNK = 2**16

#: Rows (sensors, or a capture's pairs) the default chunks are sized for: every sample serves every row,
#: so a scene with more rows gets proportionally fewer samples per chunk (a 1024-pair scan 2^16 on a CPU),
#: and a chunk, hence the time between checkpoints, stays under a second or so whatever the scan.
CHUNK_ROWS = 16


def default_chunk(rows: int, gpu: bool) -> int:
    """The largest chunk, samples, for a scene of ``rows`` sensors or pairs: :data:`DEFAULT_CHUNK` (CPU)
    or :data:`DEFAULT_CHUNK_GPU` at up to :data:`CHUNK_ROWS` rows, in proportion fewer beyond (a power of
    two, at least 1)."""
    largest = DEFAULT_CHUNK_GPU if gpu else DEFAULT_CHUNK
    if rows <= CHUNK_ROWS:
        return largest
    return 1 << max(0, (largest * CHUNK_ROWS // rows).bit_length() - 1)

#: Where an unfinished render's current estimate goes (``meta.json`` says ``"complete": false``).
PARTIAL_FOLDER = "partial"

#: The replica means, ``(R, K, N)`` float64, beside ``transient.npy`` and ``stderr.npy``.
REPLICAS_FILE = "replicas.npy"

# Seconds between checkpoints: often enough that an interruption loses
# little, rarely enough that fsyncs do not slow small chunks down.
_CHECKPOINT_SECONDS = 5.0

# What write_transient and this module write into a partial folder (and nothing else is removed from it).
_OUTPUT_FILES = ("transient.npy", "transient.exr", "transient.h5", "stderr.npy", REPLICAS_FILE, "meta.json")

#: The figure ``diffuse-imaging render`` draws beside a complete render's files.
FIGURE_FILE = "transient.png"

# A complete render's files: an earlier render's are removed when a new render's first state replaces its
# state, so that a folder never shows complete-looking results that its state does not hold.
_FINAL_FILES = (*_OUTPUT_FILES, FIGURE_FILE)


class RenderInterrupted(KeyboardInterrupt):
    """A render stopped by Ctrl-C, SIGTERM or ``on_chunk``, after its finished chunks were saved.

    Attributes
    ----------
    done : int
        Samples done (and saved, when ``folder`` is set).
    planned : int
        Samples of the whole render, R n.
    completed, replicas : int
        Replicas complete, of R.
    folder : Path or None
        The folder holding the state to resume from (None: nothing saved).
    """

    def __init__(self, *, done: int, planned: int, completed: int, replicas: int, folder: Path | None):
        self.done, self.planned, self.completed, self.replicas = done, planned, completed, replicas
        self.folder = folder
        saved = f"; the state is in {folder}" if folder is not None else "; nothing was saved"
        super().__init__(f"interrupted after {done:,} of {planned:,} samples ({completed} of {replicas} "
                         f"replicas complete){saved}")


@dataclass(frozen=True)
class RenderResult:
    """A Monte Carlo estimate of y_k[n].

    Attributes
    ----------
    mean : numpy.ndarray
        ``(K, N)`` float64 estimate of y_k[n] (units of y: W/sr x m⁻² x m
        of path length, :data:`analytic.files.UNITS`).
    stderr : numpy.ndarray
        ``(K, N)`` float64 standard error of ``mean``, from the replicas.
    replica_means : numpy.ndarray
        ``(R, K, N)`` float64: each replica's own estimate of y; ``mean`` is
        their mean and ``stderr`` their standard deviation over sqrt(R).
    samples : int
        Samples drawn, R n (points on the plane; each serves every sensor).
    drawn : int
        Samples drawn by this call (less than ``samples`` after a resume).
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
    replica_means: np.ndarray
    samples: int
    drawn: int
    seed: int
    variant: str
    seconds: float
    replicas: int
    dof: int


def _result(accumulator: ReplicaAccumulator, scale: float, *, drawn: int, seed: int, variant: str,
            seconds: float) -> RenderResult:
    """The accumulator's estimate times ``scale`` (the source intensity when it rendered per unit of it)."""
    return RenderResult(mean=accumulator.mean() * scale, stderr=accumulator.stderr() * scale,
                        replica_means=accumulator.replica_means() * scale, samples=accumulator.samples,
                        drawn=int(drawn), seed=int(seed), variant=variant, seconds=seconds,
                        replicas=accumulator.completed, dof=accumulator.dof)


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

    For scenes that are not an :class:`analytic.scenes.common.Scene` (the corner of
    ``transient.mitsuba_scene.corner_scene_dict``, an exported XML), rendered
    with the same replicas and chunks as :func:`render`, each chunk in units
    of y (the integrator's ``render_chunk``).

    Parameters
    ----------
    loaded : mitsuba.Scene
        Loaded with ``transient_opl`` or ``transient_opl_path`` (a ``transient_opl_nlos`` scene is
        refused: it renders per unit laser intensity).
    spp, seed, replicas, chunk_size
        As for :func:`render`.
    """
    import mitsuba as mi

    if chunk_size is None:
        chunk_size = default_chunk(len(loaded.sensors()), mi.variant().startswith("cuda"))
    _check_arguments(spp, seed, chunk_size, replicas)
    layout = ReplicaLayout.for_samples(int(spp), replicas)
    integrator = loaded.integrator()
    if not hasattr(integrator, "render_chunk"):
        # transient_opl_nlos holds no laser intensity: it renders per unit intensity only
        raise ValueError(f"render_loaded: {type(integrator).__name__} renders per unit laser intensity; render "
                         f"the RelayWallScene with transient.render.render, or call its "
                         f"render_chunk_per_unit_intensity and multiply by I")
    shape = (len(loaded.sensors()), int(integrator.bins))
    accumulator = ReplicaAccumulator(layout, shape)
    started = time.perf_counter()
    for chunk in _chunks(0, layout.samples, int(chunk_size)):
        accumulator.add(chunk, integrator.render_chunk(loaded, seed=int(seed), layout=layout, first=chunk.first,
                                                       count=chunk.count))
    return _result(accumulator, 1.0, drawn=accumulator.done, seed=seed, variant=mi.variant(),
                   seconds=time.perf_counter() - started)


def _check_arguments(spp, seed, chunk_size, replicas):
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)):
        raise OptionError(f"spp: must be an integer, got {spp!r}")
    if not 2 <= spp <= MAX_SAMPLES:
        raise OptionError(f"spp: must be in [2, 2^48] (2^48 samples take about 108 days at 3e7 samples/s on "
                          f"2 CPU cores, 4 hours at 2e10 samples/s on a GPU), got {spp}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise OptionError(f"seed: must be an integer in [0, 2^32), got {seed!r}")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) \
            or not 1 <= chunk_size <= 2**31:
        raise OptionError(f"chunk_size: must be an integer in [1, 2^31], got {chunk_size!r}")
    if replicas is not None and (isinstance(replicas, bool) or not isinstance(replicas, (int, np.integer))
                                 or not 2 <= replicas <= spp):
        raise OptionError(f"replicas: must be an integer in [2, spp = {spp}], got {replicas!r}")


def _remove_partial(folder: Path) -> None:
    """Remove ``folder/partial`` (only the files a render writes there, then the folder if empty)."""
    partial = folder / PARTIAL_FOLDER
    # A stale partial estimate beside complete outputs is labelled ("complete": false), never wrong.
    with contextlib.suppress(OSError):
        for name in _OUTPUT_FILES:
            (partial / name).unlink(missing_ok=True)
        if partial.is_dir():
            partial.rmdir()


class _Outputs:
    """The files a render writes into its folder: state, scene, and the estimate (partial or complete)."""

    def __init__(self, folder: Path, scene: Scene, identity: dict, *, fresh: bool):
        self.folder, self.scene, self.identity = folder, scene, identity
        # Written again by every run (a resumed one too): a damaged or missing copy is repaired.
        self.scene_saved = False
        # A new render replaces the folder's state: an earlier render's results go with it.
        self.fresh = fresh
        self.share = window_share(scene)

    def checkpoint(self, accumulator: ReplicaAccumulator, *, complete: bool) -> None:
        """Save the scene (first time), then the state, then the estimate once 2 replicas are complete."""
        if not self.scene_saved:
            save_scene(self.folder, self.scene)
            self.scene_saved = True
        with staged_writes():
            save_state(self.folder / STATE_FILE, self.identity, accumulator)
            for name in _FINAL_FILES if self.fresh else ():
                discard(self.folder / name)
        self.fresh = False
        if accumulator.completed < 2:
            return
        identity = self.identity
        meta = build_meta(self.scene, kind="render", samples=int(accumulator.samples), seed=identity["seed"],
                          window_share=self.share, variant=identity["variant"],
                          requested_samples=identity["requested"], scene_fingerprint=identity["fingerprint"],
                          replicas=int(accumulator.completed), dof=int(accumulator.dof), complete=bool(complete))
        estimate = _result(accumulator, float(self.scene.intensity), drawn=0, seed=identity["seed"],
                           variant=identity["variant"], seconds=0.0)
        target = self.folder if complete else self.folder / PARTIAL_FOLDER
        with staged_writes():
            write_transient(target, estimate.mean, meta, scene=self.scene, stderr=estimate.stderr)
            save_npy(target / REPLICAS_FILE, estimate.replica_means)
        if complete:
            _remove_partial(self.folder)


def _load_plane(scene, estimator: dict):
    from .mitsuba_scene import load_scene

    return load_scene(scene, **estimator)


def _load_relay_wall(scene, estimator: dict):
    import mitsuba as mi

    from .mitsuba_scene import relay_wall_scene_dict

    return mi.load_dict(relay_wall_scene_dict(scene, **estimator))


#: The Mitsuba scene of each scene kind: a plane (``transient_opl``), a relay-wall capture (``transient_opl_nlos``).
_LOADERS = {"plane": _load_plane, "relay_wall": _load_relay_wall}


def _load(scene, estimator: dict):
    """The loaded Mitsuba scene of ``scene`` (its kind's loader, :data:`_LOADERS`)."""
    return for_kind(_LOADERS, scene, "render")(scene, estimator)


def render(scene: Scene, *, spp: int, seed: int = 0, out_dir: str | Path | None = None,
           variant: str | None = None, resume: bool = False, chunk_size: int | None = None,
           progress: bool = True, on_chunk: Callable[[int], None] | None = None,
           replicas: int | None = None, estimator: dict | None = None) -> RenderResult:
    """Monte Carlo estimate of the scene's transient y_k[n] and its standard error.

    Parameters
    ----------
    scene : Scene or analytic.scenes.relay_wall.RelayWallScene
        The scene, rendered with its ``attenuation`` (``lambertian`` or
        ``paper``) and intensity (float64); its ``tolerance`` and ``noise``
        belong to the model and are not read. A relay-wall capture renders
        with ``transient_opl_nlos`` (third bounce, its pairs as the rows).
    spp : int
        Samples (points on the plane or the hidden rectangle; each serves all K sensors or P pairs),
        2 <= spp <= 2^48. The render draws R ⌈spp / R⌉, up to R - 1 more.
    seed : int
        Seed, 0 <= seed < 2^32; sample g depends on (seed, g) only.
    out_dir : str or Path, optional
        Folder for checkpoints and outputs (see the module's docstring).
    variant : str, optional
        Mitsuba variant; see :func:`transient.backend.select_variant`.
    resume : bool
        Continue from ``out_dir/render_state.npz`` (same scene, seed,
        variant, ``spp``, ``replicas`` and estimator);
        :class:`~transient.render_state.RenderStateError` if it cannot.
        :func:`resume` needs only the folder.
    chunk_size : int, optional
        Most samples per kernel launch (memory and checkpoint granularity),
        1 <= chunk_size <= 2^31. Default :func:`default_chunk`: 2^22 on a
        CPU, 2^30 on a CUDA variant, fewer for scenes of more than 16
        sensors or pairs.
    progress : bool
        Show a tqdm progress bar over samples (on stderr).
    on_chunk : callable, optional
        Called with the number of samples done after each finished chunk has
        been added to the totals; it may raise KeyboardInterrupt to stop the
        render as Ctrl-C would (checkpoint written, :class:`RenderInterrupted`
        raised).
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
    analytic.errors.OptionError
        A bad argument, before any work (a ValueError too).
    RenderStateError
        ``resume`` and a state that cannot be resumed.
    analytic.errors.ResourceError
        The replicas would not fit in memory (before any work), or a file
        cannot be written.
    transient.backend.BackendError
        The variant cannot run here (no CUDA device, old libLLVM).
    RenderInterrupted
        On Ctrl-C, SIGTERM or from ``on_chunk``, after the finished chunks
        have been written to ``out_dir`` (a KeyboardInterrupt).
    """
    gpu = variant is not None and str(variant).startswith("cuda")
    chunk_size = default_chunk(scene.sensor_count, gpu) if chunk_size is None else chunk_size
    _check_arguments(spp, seed, chunk_size, replicas)
    spp, seed, chunk_size = int(spp), int(seed), int(chunk_size)
    if resume and out_dir is None:
        raise OptionError("resume: needs out_dir")
    layout = ReplicaLayout.for_samples(spp, replicas)
    estimator = dict(estimator or {})
    shape = (scene.sensor_count, scene.sampling.count)

    from .backend import select_variant

    variant = select_variant(variant)
    from .common import per_thread_copies

    copies = per_thread_copies(layout.histogram_rows * shape[0] * shape[1])
    require_memory(render_memory_bytes(layout, shape, copies),
                   f"{layout.replicas} replicas x {shape[0]} sensors x {shape[1]} bins",
                   "use fewer bins (sampling.count), sensors or replicas")
    fingerprint = scene_fingerprint(scene, estimator)
    identity = state_identity(fingerprint, seed, variant, layout, spp, estimator)
    out_dir = Path(out_dir) if out_dir is not None else None
    accumulator = (load_state(out_dir, identity, layout, shape) if resume
                   else ReplicaAccumulator(layout, shape))
    outputs = None
    if out_dir is not None:
        outputs = _Outputs(out_dir, scene, identity, fresh=not resume)
        if not resume:
            _remove_partial(out_dir)          # an earlier render's estimate, not this one's
    started_at = accumulator.done
    bar = None
    try:
        with sigterm_as_interrupt():
            loaded = _load(scene, estimator)
            integrator = loaded.integrator()
            if progress:
                from tqdm import tqdm
                bar = tqdm(total=layout.samples, initial=accumulator.done, unit="sample", unit_scale=True,
                           desc="render", leave=False)
            started = time.perf_counter()
            last_checkpoint = None
            for chunk in _chunks(accumulator.done, layout.samples, chunk_size):
                sums = integrator.render_chunk_per_unit_intensity(loaded, seed=seed, layout=layout,
                                                                  first=chunk.first, count=chunk.count)
                accumulator.add(chunk, sums)
                if bar is not None:
                    bar.update(chunk.count)
                now = time.perf_counter()
                # The first chunk (small) is checkpointed at once; then every few seconds.
                if outputs is not None and (last_checkpoint is None
                                            or now - last_checkpoint >= _CHECKPOINT_SECONDS):
                    outputs.checkpoint(accumulator, complete=False)
                    last_checkpoint = time.perf_counter()
                if on_chunk is not None:
                    on_chunk(accumulator.done)
            seconds = time.perf_counter() - started
    except KeyboardInterrupt:
        if outputs is not None:
            outputs.checkpoint(accumulator, complete=False)
        raise RenderInterrupted(done=accumulator.done, planned=layout.samples, completed=accumulator.completed,
                                replicas=layout.replicas, folder=out_dir) from None
    finally:
        if bar is not None:
            bar.close()
    if outputs is not None:
        outputs.checkpoint(accumulator, complete=True)
    # The replicas are per unit intensity: I (float64, the scene's own) enters once, here.
    return _result(accumulator, float(scene.intensity), drawn=accumulator.done - started_at, seed=seed,
                   variant=variant, seconds=seconds)


def resume(out_dir: str | Path, *, scene: Scene | None = None, spp: int | None = None, seed: int | None = None,
           variant: str | None = None, chunk_size: int | None = None, progress: bool = True,
           on_chunk: Callable[[int], None] | None = None) -> RenderResult:
    """Finish the render saved in ``out_dir``, from the folder alone.

    Parameters
    ----------
    out_dir : str or Path
        The folder of an unfinished (or finished) render.
    scene, spp, seed, variant : optional
        Given again, each must match the state's (the scene by its
        fingerprint; its ``noise``, ``tolerance`` and name may differ and
        go to ``meta.json``); left out, the state's are used.
    chunk_size, progress, on_chunk
        As for :func:`render`.

    Raises
    ------
    RenderStateError
        The state or the saved scene cannot be read, or an argument given
        differs from the state's (each named, on one line, before any
        work: a scene by the keys that differ).
    """
    saved = read_saved_render(out_dir, scene=scene, spp=spp, seed=seed, variant=variant)
    return render(saved.scene, spp=saved.spp, seed=saved.seed, out_dir=saved.folder, variant=saved.variant,
                  resume=True, chunk_size=chunk_size, progress=progress, on_chunk=on_chunk,
                  replicas=saved.replicas, estimator=saved.estimator)
