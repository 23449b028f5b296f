"""Every shell and Python snippet of README.md and docs/*.md runs, exactly as written.

A snippet is a fenced block; the words after its opening fence (the info
string) say what this test does with it:

- ``bash``, ``sh``, ``python``: run, and must exit 0. Shell snippets run with
  ``-e`` (and bash's ``-o pipefail``), so a failing command inside one fails
  it; a command expected to fail says so in the snippet (``|| echo ...``).
- the same followed by ``slow`` (a block opened with three backticks and
  ``bash slow``): run only with ``-m slow``, for renders, sweeps and
  mitransient runs that take minutes.
- ``bash setup``: shown, not run here: the set-up and the test suite itself.
  CI (``.ci/run``) runs them on a clean clone; a test below holds its
  command equal to the README's.
- ``text``: output, not run. ``toml``: parsed; a block whose tables are all
  scene tables is read as a scene (``analytic.scene_from_dict``), except in
  docs/design.md, whose sections 7 and 8 state keys still to be built.
- any other info string is refused, so that a typo cannot hide a snippet.

Each document's snippets run in order in one temporary folder that holds a
copy of the repository's ``examples/`` (and ``.venv-tal`` where the set-up
made it), as a user's clone would: a snippet may use what an earlier one of
the same document wrote. A snippet run alone first runs the earlier ones it
may depend on (every earlier snippet for a slow one, the earlier fast ones
for a fast one). Commands run as ``diffuse-imaging`` and ``python3`` from the
interpreter that runs the tests.

Links are checked too: every relative link of README.md and docs/*.md names
a file of the repository (the README's none outside it: a clone has no
``../shared``), and every ``#anchor`` a heading of its page.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

#: Info-string languages this test runs, and how.
RUN = {"bash": ["bash", "-e", "-o", "pipefail", "-c"], "sh": ["sh", "-e", "-c"], "python": None}
#: Info strings shown but not run (see the module's docstring).
NOT_RUN = {"bash setup", "text", "toml"}
#: Seconds a snippet may take: a fast one, and a slow one.
TIMEOUT = {False: 300, True: 1200}

_FENCE = re.compile(r"^```(.*)$")
_LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


@dataclass(frozen=True)
class Snippet:
    """One fenced block: its document, first line (1-based), info string and text."""

    document: Path
    line: int
    info: str
    code: str

    @property
    def language(self) -> str:
        return self.info.split()[0] if self.info else ""

    @property
    def slow(self) -> bool:
        return self.info.split()[1:] == ["slow"]

    @property
    def runnable(self) -> bool:
        return self.language in RUN and self.info not in NOT_RUN

    @property
    def name(self) -> str:
        return f"{self.document.relative_to(ROOT)}:{self.line}"


def snippets(document: Path) -> list[Snippet]:
    """The fenced blocks of a Markdown file, in order."""
    found, info, start, lines = [], None, 0, []
    for number, line in enumerate(document.read_text(encoding="utf-8").splitlines(), start=1):
        match = _FENCE.match(line)
        if info is None and match:
            info, start, lines = match.group(1).strip(), number, []
        elif info is not None and line.rstrip() == "```":
            found.append(Snippet(document, start, info, "\n".join(lines) + "\n"))
            info = None
        elif info is not None:
            lines.append(line)
    assert info is None, f"{document}:{start}: a fence is never closed"
    return found


ALL = [snippet for document in DOCUMENTS for snippet in snippets(document)]
RUNNABLE = [snippet for snippet in ALL if snippet.runnable]


def _environment() -> dict:
    """The user's environment, with this interpreter's scripts (diffuse-imaging, python3) first on PATH."""
    environment = dict(os.environ)
    scripts = str(Path(sys.executable).parent)
    environment["PATH"] = scripts + os.pathsep + environment.get("PATH", "")
    environment["MPLBACKEND"] = "Agg"
    return environment


class Workspace:
    """A document's folder: a copy of examples/, and which of its snippets ran, with what outcome."""

    def __init__(self, folder: Path):
        self.folder = folder
        shutil.copytree(ROOT / "examples", folder / "examples",
                        ignore=shutil.ignore_patterns("__pycache__", "out"))
        for venv in (".venv-tal", ".venv-tal-render"):         # tal, and tal with its renderer (docs/tal.md)
            if (ROOT / venv).is_dir():
                (folder / venv).symlink_to(ROOT / venv)
        self.outcomes: dict[int, str | None] = {}      # snippet line -> None (ran) or the failure

    def run(self, snippet: Snippet) -> str | None:
        """Run ``snippet`` once; the failure's description, or None."""
        if snippet.line in self.outcomes:
            return self.outcomes[snippet.line]
        if snippet.language == "python":
            script = self.folder / f".snippet-{snippet.line}.py"
            script.write_text(snippet.code, encoding="utf-8")
            command = [sys.executable, script.name]
        else:
            command = [*RUN[snippet.language], snippet.code]
        try:
            done = subprocess.run(command, cwd=self.folder, env=_environment(), capture_output=True, text=True,
                                  timeout=TIMEOUT[snippet.slow])
            failure = None if done.returncode == 0 else (
                f"{snippet.name} exited {done.returncode}\n--- snippet\n{snippet.code}--- stdout (end)\n"
                f"{done.stdout[-3000:]}\n--- stderr (end)\n{done.stderr[-3000:]}")
        except subprocess.TimeoutExpired:
            failure = f"{snippet.name} ran past {TIMEOUT[snippet.slow]} s\n--- snippet\n{snippet.code}"
        self.outcomes[snippet.line] = failure
        return failure


@pytest.fixture(scope="session")
def workspaces(tmp_path_factory):
    made = {}

    def workspace(document: Path) -> Workspace:
        if document not in made:
            made[document] = Workspace(tmp_path_factory.mktemp(document.stem))
        return made[document]

    return workspace


def _marked(snippet: Snippet):
    return pytest.param(snippet, id=snippet.name, marks=[pytest.mark.slow] if snippet.slow else [])


@pytest.mark.parametrize("snippet", [_marked(snippet) for snippet in RUNNABLE])
def test_snippet_runs_as_written(snippet, workspaces):
    workspace = workspaces(snippet.document)
    earlier = [other for other in RUNNABLE if other.document == snippet.document and other.line < snippet.line
               and (snippet.slow or not other.slow)]
    for other in earlier:
        failure = workspace.run(other)
        assert failure is None, f"an earlier snippet of {snippet.document.name} failed:\n{failure}"
    failure = workspace.run(snippet)
    assert failure is None, failure


def test_the_commands_the_snippets_call_are_installed():
    """``diffuse-imaging`` beside this interpreter (``scripts/setup.sh``: ``pip install -e .``), as a user has it."""
    path = _environment()["PATH"]
    assert shutil.which("diffuse-imaging", path=path), "diffuse-imaging is not installed: run scripts/setup.sh"
    assert shutil.which("python3", path=path)


def test_every_fenced_block_says_what_it_is():
    """Run, not run, or output: no fence without an info string, no unknown one (a typo hides nothing)."""
    known = {*RUN, *(f"{language} slow" for language in RUN), *NOT_RUN}
    unknown = [f"{snippet.name}: ```{snippet.info}" for snippet in ALL if snippet.info not in known]
    assert not unknown, "fenced blocks this test does not know:\n" + "\n".join(unknown)


def test_the_snippets_are_found():
    """The parser sees the README's tour: a broken fence would silently skip every snippet after it."""
    readme = [snippet for snippet in RUNNABLE if snippet.document.name == "README.md"]
    assert any("diffuse-imaging forward examples/paper.toml" in snippet.code for snippet in readme)
    assert any(snippet.language == "python" for snippet in readme)


_SCENE_TABLES = {"name", "plane", "source", "illumination", "sensors", "sampling", "model", "noise"}
_RELAY_WALL_TABLES = {"name", "relay_wall", "hidden", "laser", "sensor", "scan", "illumination", "sampling", "model",
                      "noise"}


@pytest.mark.parametrize("snippet", [pytest.param(snippet, id=snippet.name) for snippet in ALL
                                     if snippet.info == "toml"])
def test_toml_blocks_parse_and_scene_blocks_are_scenes(snippet):
    import analytic

    data = tomllib.loads(snippet.code)
    # docs/design.md also states contracts of work in progress (its sections 7 and 8): parsed only
    scene = set(data) <= _SCENE_TABLES or ("relay_wall" in data and set(data) <= _RELAY_WALL_TABLES)
    if scene and snippet.document.name != "design.md":
        analytic.scene_from_dict(data, ROOT / "examples")


def test_ci_runs_exactly_the_readmes_test_command():
    """.ci/run runs the README's test command, character for character."""
    setup = next(snippet for snippet in ALL if snippet.document.name == "README.md" and snippet.info == "bash setup")
    commands = [line.split("#")[0].strip() for line in setup.code.splitlines()]
    test_command = next(command for command in commands if "pytest" in command)
    ci_lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()]
    assert test_command in ci_lines


def _anchors(document: Path) -> set[str]:
    """GitHub's anchors for a page's headings: lower case, punctuation dropped, spaces as hyphens."""
    anchors = set()
    for line in document.read_text(encoding="utf-8").splitlines():
        if line.startswith("#") and not line.startswith("#!"):
            title = line.lstrip("#").strip().lower()
            anchors.add(re.sub(r"\s", "-", re.sub(r"[^\w\- ]", "", title)))
    return anchors


def _inside_fences(document: Path) -> set[int]:
    """Line numbers inside fenced blocks (their links are code, not links)."""
    inside, fenced = set(), False
    for number, line in enumerate(document.read_text(encoding="utf-8").splitlines(), start=1):
        if not fenced and _FENCE.match(line):
            fenced = True
        elif fenced and line.rstrip() == "```":
            fenced = False
        elif fenced:
            inside.add(number)
    return inside


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda path: str(path.relative_to(ROOT)))
def test_every_relative_link_names_a_file_and_heading_of_the_repository(document):
    problems = []
    fenced = _inside_fences(document)
    for number, line in enumerate(document.read_text(encoding="utf-8").splitlines(), start=1):
        if number in fenced:
            continue
        for target in _LINK.findall(line):
            if re.match(r"[a-z]+:", target):
                continue                               # http:, https:, mailto:
            path, _, anchor = target.partition("#")
            linked = (document.parent / path).resolve() if path else document
            if ROOT not in [linked, *linked.parents]:
                problems.append(f"{number}: {target} leaves the repository (a clone lacks it)")
            elif not linked.exists():
                problems.append(f"{number}: {target} does not exist")
            elif anchor and linked.suffix == ".md" and anchor not in _anchors(linked):
                problems.append(f"{number}: {target}: no heading of {linked.name} has that anchor")
    assert not problems, f"{document.name}:\n" + "\n".join(problems)


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda path: str(path.relative_to(ROOT)))
def test_no_document_cites_the_folders_beside_the_repository(document):
    """``../shared/...`` (the letter, the contract's first home) exists beside the working copy, not in a clone."""
    text = document.read_text(encoding="utf-8")
    assert "../shared" not in text and "shared/DESIGN.md" not in text


def test_the_readme_stays_a_tour():
    """The long reference lives in docs/; the README keeps to about 260 lines (270 at most)."""
    assert len((ROOT / "README.md").read_text(encoding="utf-8").splitlines()) <= 270
