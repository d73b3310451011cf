"""The README and docs/: every relative link resolves, every doc is reached from the index,
and every `python -m rtcohand_drake...` command they show answers --help."""

import os
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from urllib.parse import unquote

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
INDEX = REPO / "docs" / "README.md"

# [text](target) and ![alt](target); a target ends at whitespace or the closing parenthesis.
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
MODULE = re.compile(r"python3? -m (rtcohand_drake(?:\.[A-Za-z_][A-Za-z0-9_]*)*)")


def _relative_links(path: Path) -> list[str]:
    targets = LINK.findall(path.read_text())
    return [t for t in targets if not re.match(r"[a-z][a-z0-9+.-]*:", t) and not t.startswith("#")]


def test_there_are_docs_and_an_index():
    assert INDEX.is_file()
    assert len(DOCS) >= 10


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_resolves(path):
    missing = []
    for target in _relative_links(path):
        file = unquote(target.split("#", 1)[0])
        if not (path.parent / file).exists():
            missing.append(target)
    assert not missing, f"{path.relative_to(REPO)}: links to nothing: {missing}"


def test_the_index_links_every_doc():
    linked = {(INDEX.parent / unquote(t.split("#", 1)[0])).resolve() for t in _relative_links(INDEX)}
    unlinked = [p.name for p in DOCS if p.parent == INDEX.parent and p != INDEX and p.resolve() not in linked]
    assert not unlinked, f"docs/README.md does not link {unlinked}"


def _modules() -> list[str]:
    found = set()
    for path in DOCS:
        found.update(MODULE.findall(path.read_text()))
    # A placeholder in prose (`python -m rtcohand_drake.X`) names no module.
    return sorted(m for m in found if not m.rsplit(".", 1)[-1].isupper())


def test_commands_are_found():
    modules = _modules()
    assert {"rtcohand_drake.run", "rtcohand_drake.context_reading", "rtcohand_drake.record"} <= set(modules)


def test_every_command_shown_answers_help():
    """Each distinct module, once: `python -m MODULE --help` exits 0 (two at a time: each loads Drake or torch)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))

    def run(module):
        proc = subprocess.run([sys.executable, "-m", module, "--help"], cwd=REPO, env=env, capture_output=True,
                              text=True, timeout=120)
        answered = proc.returncode == 0 and proc.stdout.lstrip().startswith("usage:")
        return module, answered, proc.stderr[-400:]

    with ThreadPoolExecutor(max_workers=2) as pool:
        failed = [(m, err) for m, answered, err in pool.map(run, _modules()) if not answered]
    assert not failed, failed


def test_every_benchmark_is_cited_by_a_doc():
    """benchmarks/ holds what the docs cite; a one-off study belongs in experiments/, with a row in its index."""
    text = "\n".join(p.read_text() for p in DOCS)
    uncited = [p.name for p in sorted((REPO / "benchmarks").iterdir())
               if p.is_file() and f"benchmarks/{p.name}" not in text]
    assert not uncited, uncited
    index = (REPO / "experiments" / "README.md").read_text()
    unlisted = [p.name for p in sorted((REPO / "experiments").glob("*.py")) if f"`{p.name}`" not in index]
    assert not unlisted, unlisted
