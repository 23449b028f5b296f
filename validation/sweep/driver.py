"""Running a sweep on a Dask cluster: chunks as tasks, checkpoints, resumption.

Each item's render is split into fixed chunks of the sample range; sample
i's random numbers depend only on (seed, i), so chunks are independent,
deterministic tasks: any worker may compute any chunk, a chunk lost with its
worker is computed again, and the driver adds the chunks' float64 moments in
chunk order.
"""

from __future__ import annotations

import contextlib
import logging
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from transient.render import sigterm_as_interrupt

from .checkpoint import CHECKPOINT_SECONDS, ItemState, layout_of, load_state, save_state
from .config import Sweep
from .index import finish_item, finished_row, write_index
from .tasks import _identity, model_transient, render_chunk

__all__ = ["SweepResult", "run_sweep", "sweep_client", "check_variant", "CONNECT_SECONDS"]

#: How long to wait for a scheduler given by address.
CONNECT_SECONDS = 10.0


@dataclass(frozen=True)
class SweepResult:
    """What :func:`run_sweep` did.

    Attributes
    ----------
    out_dir : Path
        The sweep's output folder.
    rows : tuple of dict
        One index row per item (as in ``index.json``).
    computed_chunks : tuple of (str, int)
        (item name, chunk index) of every chunk computed by this call, in
        the order they arrived; chunks restored from checkpoints are absent.
    skipped_items : tuple of str
        Items already finished before this call.
    seconds : float
        Wall time of this call, seconds.
    workers : int
        Workers of the cluster when the sweep started.
    """

    out_dir: Path
    rows: tuple
    computed_chunks: tuple
    skipped_items: tuple
    seconds: float
    workers: int

    @property
    def all_agree(self) -> bool | None:
        """True/False when cross-checked (every item agrees or not); None otherwise."""
        verdicts = [row.get("agrees") for row in self.rows]
        if any(v is None for v in verdicts):
            return None
        return all(verdicts)


#: The extra that brings Dask (``pip install 'diffuse-imaging[sweep]'``).
EXTRA = "sweep"


def require_dask() -> None:
    """Refuse in one line, naming the extra that brings it, when Dask's ``distributed`` is not installed.

    Raises
    ------
    analytic.errors.ResourceError
    """
    import importlib.util

    from analytic.errors import ResourceError

    if importlib.util.find_spec("distributed") is None:
        raise ResourceError(f"sweep: runs on Dask, which is an optional extra not installed here; install it "
                            f"with pip install 'diffuse-imaging[{EXTRA}]'")


@contextlib.contextmanager
def sweep_client(scheduler: str | None = None, workers: int | None = None) -> Iterator:
    """A ``distributed.Client``: to the cluster at ``scheduler``, or to a new local one.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``). The cluster's
        workers must have this package installed; run them with
        ``--nthreads 1`` and one worker per core.
    workers : int, optional
        Local cluster only: worker processes (default: one per core), one
        thread each, dashboard off, listening on loopback only.
    """
    require_dask()
    from distributed import Client, LocalCluster

    if scheduler is not None:
        if workers is not None:
            raise ValueError("workers: only for a local cluster (the scheduler's cluster has its own)")
        with _connected(Client, scheduler) as client:
            yield client
        return
    workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"workers: must be >= 1, got {workers}")
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                      host="127.0.0.1", silence_logs=logging.ERROR) as cluster, \
            Client(cluster) as client:
        yield client


@contextlib.contextmanager
def _connected(client_class, scheduler: str):
    """A client of the scheduler at ``scheduler``, or one line saying why there is none."""
    from analytic.errors import ResourceError

    try:
        client = client_class(scheduler, timeout=CONNECT_SECONDS)
    except (OSError, TimeoutError) as error:
        raise ResourceError(f"--scheduler {scheduler}: no Dask scheduler answered within "
                            f"{CONNECT_SECONDS:g} s ({type(error).__name__}); start one there "
                            f"(dask scheduler) or leave --scheduler out for a local cluster") from None
    except (ValueError, TypeError) as error:
        raise ResourceError(f"--scheduler {scheduler}: not a scheduler address ({error}); "
                            f"give one such as tcp://host:8786") from None
    with client:
        yield client


def check_variant(variant: str | None) -> str:
    """The Mitsuba variant a local cluster's workers will render with, or a one-line refusal.

    A local cluster's workers run on this machine, so a variant it cannot
    run (a CUDA variant without a GPU, one this Mitsuba build lacks, a CPU
    variant with only libLLVM <= 15) is refused here, before any cluster
    starts or any file is written, instead of failing in every task.

    Parameters
    ----------
    variant : str or None
        The sweep's ``variant`` (None: the CPU default).

    Returns
    -------
    str
        The variant, now active in this process too.

    Raises
    ------
    transient.backend.BackendError
        A :class:`analytic.errors.ResourceError`, one line with the fix.
    """
    from transient.backend import select_variant

    return select_variant(variant)


def _check_variant_on_a_worker(client, variant: str | None) -> None:
    """A cluster given by address runs elsewhere: ask one of its workers, before any file is written."""
    from transient.backend import select_variant

    client.submit(select_variant, variant, pure=False).result()


def _prepare(sweep: Sweep, out_dir: Path) -> tuple[dict, dict, list]:
    """Finished items' rows, unfinished items' checkpointed states, and the names skipped."""
    from analytic.operator.window import window_share
    from transient.render_state import scene_fingerprint

    rows, states, skipped = {}, {}, []
    for item in sweep.items:
        folder = out_dir / item.name
        fingerprint = scene_fingerprint(item.scene)
        row = finished_row(item, folder, sweep, fingerprint)
        if row is not None:
            rows[item.name] = row
            skipped.append(item.name)
            continue
        state = load_state(item, folder, sweep, fingerprint)
        state.window_share = window_share(item.scene)
        states[item.name] = state
    return rows, states, skipped


def run_sweep(sweep: Sweep, out_dir: str | Path, *, client=None, scheduler: str | None = None,
              workers: int | None = None, progress: bool = True, retries: int = 3,
              on_chunk: Callable[[str, int], None] | None = None) -> SweepResult:
    """Render (and cross-check) every item of a sweep on a Dask cluster, resumably.

    Parameters
    ----------
    sweep : Sweep
        The validated sweep.
    out_dir : str or Path
        Output folder: one sub-folder per item, ``index.json``, ``index.csv``.
        Items finished there already are skipped; unfinished ones resume
        from their checkpointed chunks.
    client : distributed.Client, optional
        Use this client (``scheduler`` and ``workers`` must then be None).
    scheduler : str, optional
        Address of a running Dask scheduler; default: start a local cluster.
    workers : int, optional
        Local cluster size (default: one worker per core).
    progress : bool
        tqdm bars over items and samples (on stderr).
    retries : int
        Times Dask re-runs a chunk whose task raised; a chunk whose worker
        died is re-run anyway (Dask's ``allowed-failures``, 3 by default).
    on_chunk : callable, optional
        ``on_chunk(item_name, chunk_index)`` after every chunk computed by
        this call has been added to its item; it may raise
        KeyboardInterrupt to stop the sweep as Ctrl-C would.

    Returns
    -------
    SweepResult

    Raises
    ------
    analytic.errors.ResourceError
        When Dask is not installed (the ``sweep`` extra), before anything is done.
    KeyboardInterrupt
        After the finished chunks of every unfinished item are checkpointed
        and the cluster's outstanding tasks cancelled.
    SceneError
        When ``out_dir`` holds an item of another sweep (other scene, seed,
        sample count or chunking).
    transient.backend.BackendError
        When the workers cannot run the sweep's variant (:func:`check_variant`),
        before anything is written.
    """
    require_dask()
    out_dir = Path(out_dir)
    if client is not None and (scheduler is not None or workers is not None):
        raise ValueError("give either client or scheduler/workers, not both")
    # Prepared before any cluster starts: another sweep's folder is refused at once.
    prepared = _prepare(sweep, out_dir)
    if client is None:
        if scheduler is None:
            check_variant(sweep.variant)       # the local workers are this machine
        with sweep_client(scheduler, workers) as own:
            if scheduler is not None:
                _check_variant_on_a_worker(own, sweep.variant)
            return _run(sweep, out_dir, own, prepared, progress=progress, retries=retries,
                        on_chunk=on_chunk)
    _check_variant_on_a_worker(client, sweep.variant)
    return _run(sweep, out_dir, client, prepared, progress=progress, retries=retries, on_chunk=on_chunk)


def _run(sweep: Sweep, out_dir: Path, client, prepared, *, progress, retries, on_chunk) -> SweepResult:
    """run_sweep's work on a connected client, from :func:`_prepare`'s result."""
    from distributed import as_completed

    started = time.perf_counter()
    rows, states, skipped = prepared
    out_dir.mkdir(parents=True, exist_ok=True)
    write_index(out_dir, sweep, rows)
    worker_count = len(client.nthreads())

    tasks = {}   # future -> (item name, chunk index or None for the model)
    for state in states.values():
        item = state.item
        # Earlier items first, so a long sweep finishes items one after another.
        priority = -item.index
        scene_future = client.submit(_identity, item.scene, pure=False, priority=priority)
        for chunk in state.plan:
            if chunk.index not in state.chunk_sums:
                future = client.submit(render_chunk, scene_future, state.fingerprint, sweep.seed,
                                       state.plan.layout, chunk, sweep.variant, pure=False, retries=retries,
                                       priority=priority)
                tasks[future] = (item.name, chunk.index)
        if sweep.cross_check:
            tasks[client.submit(model_transient, scene_future, pure=False, retries=retries,
                                priority=priority)] = (item.name, None)
        del scene_future   # the chunk tasks hold it; released when they finish

    samples = layout_of(sweep).samples       # R n: the requested count rounded up to whole replicas
    total_samples = samples * len(sweep.items)
    done_samples = samples * len(rows) + sum(state.samples_done for state in states.values())
    bars = []
    if progress:
        from tqdm import tqdm
        bars = [tqdm(total=len(sweep.items), initial=len(rows), unit="item", desc="sweep", position=0),
                tqdm(total=total_samples, initial=done_samples, unit="sample", unit_scale=True,
                     desc="samples", position=1, leave=False)]
    computed = []
    last_checkpoint = time.perf_counter()

    def finish_if_ready(state: ItemState):
        if state.complete and (not sweep.cross_check or state.model is not None):
            if state.dirty:
                save_state(state, sweep)
            rows[state.item.name] = finish_item(state, sweep, out_dir)
            del states[state.item.name]
            write_index(out_dir, sweep, rows)
            if bars:
                bars[0].update(1)

    def collect():
        nonlocal last_checkpoint
        for state in list(states.values()):
            finish_if_ready(state)   # every chunk checkpointed already, nothing to submit
        for future in as_completed(list(tasks)):
            name, chunk = tasks.pop(future)
            state = states[name]
            if chunk is None:
                state.model, state.model_seconds = future.result()
            else:
                sums, seconds, variant = future.result()
                state.chunk_sums[chunk], state.seconds[chunk], state.variant = sums, seconds, variant
                state.dirty = True
                computed.append((name, chunk))
                if bars:
                    bars[1].update(state.plan[chunk].count)
            future.release()
            finish_if_ready(state)
            now = time.perf_counter()
            if now - last_checkpoint >= CHECKPOINT_SECONDS:
                for other in states.values():
                    if other.dirty:
                        save_state(other, sweep)
                last_checkpoint = now
            if on_chunk is not None and chunk is not None:
                on_chunk(name, chunk)

    try:
        with sigterm_as_interrupt():
            collect()
    except BaseException:
        client.cancel(list(tasks))
        for state in states.values():
            if state.dirty:
                save_state(state, sweep)
        raise
    finally:
        for bar in bars:
            bar.close()
    ordered = tuple(rows[item.name] for item in sweep.items)
    return SweepResult(out_dir=out_dir, rows=ordered, computed_chunks=tuple(computed),
                       skipped_items=tuple(skipped), seconds=time.perf_counter() - started,
                       workers=worker_count)
