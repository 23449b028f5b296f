"""A sweep's index (``index.json``, ``index.csv``) and each finished item's files."""

from __future__ import annotations

import csv
import io
import json
import time
from pathlib import Path

from analytic.files import save_json, save_text, write_transient

from .checkpoint import ITEM_FILE, ItemState, mismatch, state_identity
from .config import Sweep, SweepItem

__all__ = ["finished_row", "finish_item", "write_index"]


def finished_row(item: SweepItem, folder: Path, sweep: Sweep, fingerprint: str) -> dict | None:
    """The item's index row if ``item.json`` says it is finished with these settings."""
    path = folder / ITEM_FILE
    if not path.is_file():
        return None
    row = json.loads(path.read_text(encoding="utf-8-sig"))
    identity = state_identity(sweep, fingerprint)
    if any(row.get(key) != value for key, value in identity.items()):
        raise mismatch(path, "scene, seed, sample count or chunking")
    if sweep.cross_check and row.get("agrees") is None:
        return None   # rendered, not yet cross-checked: the checkpoint has every chunk
    return row


def finish_item(state: ItemState, sweep: Sweep, out_dir: Path) -> dict:
    """Merge, write the item's files and its ``item.json``; return its index row."""
    from analytic.files import build_meta
    from validation.judging.compare import compare_transients

    scene, item = state.item.scene, state.item
    estimate = state.estimate()
    mean, stderr, dof, samples = estimate.mean(), estimate.stderr(), estimate.dof, estimate.samples
    identity = {"sweep_parameters": item.parameters, "scene_fingerprint": state.fingerprint}
    meta = build_meta(scene, kind="render", samples=samples, seed=sweep.seed,
                      window_share=state.window_share, variant=state.variant,
                      chunk_size=sweep.chunk_size, chunks=len(state.plan), replicas=estimate.completed,
                      dof=dof, **identity)
    write_transient(state.folder, mean, meta, stderr=stderr)
    compute = float(sum(state.seconds.values()))
    row = {"name": item.name, "index": item.index, "path": str(state.folder.relative_to(out_dir)),
           "parameters": item.parameters, "samples": int(samples), "requested_samples": sweep.samples,
           "seed": sweep.seed,
           "chunk_size": sweep.chunk_size, "chunks": len(state.plan), "replicas": estimate.completed,
           "dof": dof, "fingerprint": state.fingerprint,
           "render_seconds": compute, "samples_per_second": samples / compute if compute > 0 else None,
           "finished_after_seconds": time.perf_counter() - state.started, "variant": state.variant,
           "window_share": state.window_share, "agrees": None}
    if state.model is not None:
        model_meta = build_meta(scene, kind="model", window_share=state.window_share, **identity)
        write_transient(state.folder / "model", state.model, model_meta)
        agreement = compare_transients(mean, stderr, state.model, dof=dof).as_dict()
        save_json(state.folder / "agreement.json", agreement)
        row.update(agrees=agreement["agrees"], chi2_per_dof=agreement["chi2_per_dof"],
                   max_abs_z=agreement["max_abs_z"], z_threshold=agreement["z_threshold"],
                   bins=agreement["bins"], relative_l2=agreement["relative_l2"],
                   model_seconds=state.model_seconds)
    save_json(state.folder / ITEM_FILE, row)
    return row


_CSV_FIELDS = ("index", "name", "path", "samples", "seed", "chunk_size", "chunks", "render_seconds",
               "samples_per_second", "finished_after_seconds", "agrees", "chi2_per_dof", "max_abs_z",
               "z_threshold", "bins", "relative_l2", "model_seconds", "variant", "window_share")


def write_index(out_dir: Path, sweep: Sweep, rows: dict) -> None:
    """Write ``index.json`` and ``index.csv``: every item, finished or pending, in grid order."""
    ordered = []
    for item in sweep.items:
        row = rows.get(item.name)
        ordered.append(dict(row, status="done") if row is not None else
                       {"index": item.index, "name": item.name, "path": item.name,
                        "parameters": item.parameters, "status": "pending"})
    save_json(out_dir / "index.json", {"base": sweep.base, "grid": sweep.grid, "samples": sweep.samples,
                                       "seed": sweep.seed, "chunk_size": sweep.chunk_size,
                                       "cross_check": sweep.cross_check, "items": ordered})
    keys = list(sweep.grid)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["status", *_CSV_FIELDS, *keys])
    for row in ordered:
        values = [row.get(name, "") for name in _CSV_FIELDS]
        parameters = [json.dumps(row["parameters"][key]) if isinstance(row["parameters"][key], list)
                      else row["parameters"][key] for key in keys]
        writer.writerow([row["status"], *["" if v is None else v for v in values], *parameters])
    save_text(out_dir / "index.csv", buffer.getvalue())


