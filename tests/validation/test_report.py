"""The report's folders: scene names become safe, unique folder names, and nothing is written outside ``out``."""

import json
import re

import numpy as np
import pytest

from analytic.scenes.common import Sampling, Scene
from validation.judging.compare import compare_transients
from validation.runs.harness import SceneCheck
from validation.runs.report import MAX_FOLDER_NAME, RESERVED_NAMES, scene_folder_names, write_report

SAMPLING = Sampling(bin_width_opl=0.1, start_opl=1.9, count=6)


def _check(name: str, rng) -> SceneCheck:
    """A SceneCheck with a render equal to the model plus noise of its standard error (no rendering)."""
    scene = Scene(name=name, pixels=4, source=(0.5, 0.5, 1.0), sensors=[(0.2, 0.7, 1.0), (0.6, 0.3, 1.0)],
                  sampling=SAMPLING)
    model = np.outer([1.0, 2.0], [0.0, 3.0, 5.0, 4.0, 2.0, 1.0])
    stderr = np.where(model > 0, 0.01 * model, 0.0)
    render = model + stderr * rng.standard_normal(model.shape)
    agreement = compare_transients(render, stderr, model)
    return SceneCheck(name, scene, 4096, 0, model, render, stderr, agreement,
                      metrics={"agreement": agreement.as_dict()})


@pytest.mark.parametrize("name, folder", [
    ("low", "low"),                             # a safe name is kept
    ("../x", "___x"),                           # no parent folder, no leading dot
    ("/abs/x", "_abs_x"),                       # no absolute path
    (".hidden", "_hidden"),
    ("ends.", "ends_"),
    ("a b/c\\d:e", "a_b_c_d_e"),
    ("χ² scene", "___scene"),                   # ASCII only: each character outside [A-Za-z0-9._-] is one "_"
    ("", "scene"),
    ("metrics.json", "metrics.json-2"),         # names the report itself uses are never taken
    ("REPORT.MD", "REPORT.MD-2"),               # ... whatever their case
    ("model", "model-2"),
    ("transients.png", "transients.png-2"),
])
def test_a_name_becomes_a_safe_folder_name(name, folder):
    assert scene_folder_names([name]) == [folder]


def test_duplicate_names_get_numbered_suffixes_whatever_their_case():
    folders = scene_folder_names(["dup", "dup", "Dup", "dup-2", "..x", "__x"])
    assert folders == ["dup", "dup-2", "Dup-3", "dup-2-2", "__x", "__x-2"]
    assert len({folder.lower() for folder in folders}) == len(folders)


def test_folder_names_are_short_and_never_reserved():
    folders = scene_folder_names(["x" * 300, "x" * 300, *sorted(RESERVED_NAMES)])
    assert all(re.fullmatch(r"[A-Za-z0-9_-][A-Za-z0-9._-]*", folder) for folder in folders)
    assert len(folders[0]) == MAX_FOLDER_NAME and folders[1] == "x" * MAX_FOLDER_NAME + "-2"
    assert not {folder.lower() for folder in folders} & {name.lower() for name in RESERVED_NAMES}


def _files(root):
    return {path for path in root.rglob("*") if path.is_file()}


def test_validate_layout_keeps_every_file_inside_out_and_every_scene(tmp_path, rng):
    names = ["../escaped", "/abs/escaped", "metrics.json", "report.md", "dup", "dup", "Dup"]
    out = tmp_path / "deep" / "out"
    metrics = write_report(out, [_check(name, rng) for name in names])
    assert _files(tmp_path) == _files(out)                                # nothing outside out
    assert (out / "metrics.json").is_file() and (out / "report.md").is_file()
    on_disk = json.loads((out / "metrics.json").read_text())
    assert len(on_disk["scenes"]) == len(names) == len(metrics["scenes"])   # none overwrote another
    assert sorted(entry["name"] for entry in on_disk["scenes"].values()) == sorted(names)
    for folder, entry in on_disk["scenes"].items():
        assert (out / folder / "transients.png").is_file() and (out / folder / "z_map.png").is_file()
        assert entry["agreement"]["bins"] > 0
    report = (out / "report.md").read_text()
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report)
    assert len(links) == 2 * len(names) and all((out / link).is_file() for link in links)


def test_run_layout_puts_the_figures_beside_the_report(tmp_path, rng):
    out = tmp_path / "out"
    metrics = write_report(out, [_check("../default", rng)], headline=True)
    assert {path.name for path in out.iterdir()} == {"report.md", "metrics.json", "transients.png", "z_map.png"}
    assert metrics["agreement"]["bins"] > 0
    assert [entry["name"] for entry in metrics["scenes"].values()] == ["../default"]


def test_a_name_with_markdown_in_it_stays_in_its_table_cell(tmp_path, rng):
    out = tmp_path / "out"
    write_report(out, [_check("a|b", rng), _check("c", rng)])
    rows = [line for line in (out / "report.md").read_text().splitlines() if line.startswith("| a")]
    # every row of both tables has as many cells as its header
    for row in rows:
        assert len(re.split(r"(?<!\\)\|", row)) - 2 in (12, 7)
