"""The README and docs/: every relative link resolves, every doc is reached from the index,
and every `python -m rtcohand_drake...` command they show answers --help and parses."""

import contextlib
import importlib
import io
import os
import re
import shlex
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


# --------------------------------------------------------------------------- the commands quoted parse

QUOTED = [*DOCS, REPO / "models" / "README.md"]
SHELL_STOP = {"&&", "||", ";", "|", "&"}


def quoted_commands(text: str) -> list[tuple[str, list[str], bool, bool]]:
    """(module, arguments, inline, synopsis) for each `python -m rtcohand_drake...` in a page: a
    command in a code block runs to the end of its line (backslash continuations joined, a `#`
    comment, a shell operator or a redirection ends it); one in an inline code span ends at the
    span's end. A usage synopsis (`[--flag N]`, `(--a | --b)`, `a|b`, `...`) shows the syntax, not a
    command to run."""
    text = re.sub(r"\\\n[ \t]*", " ", text)
    found = []
    for m in MODULE.finditer(text):
        line_start = text.rfind("\n", 0, m.start()) + 1
        line_end = text.find("\n", m.end())
        line_end = len(text) if line_end < 0 else line_end
        before, rest = text[line_start:m.start()], text[m.end():line_end]
        inline = before.count("`") % 2 == 1
        if inline:  # up to the span's closing backtick, which may be on a later line of the paragraph
            rest = text[m.end():].split("`", 1)[0]
        elif before.count("(") > before.count(")"):  # a command named in parentheses
            rest = rest.split(")", 1)[0]
        else:  # a usage synopsis goes on in indented lines of [options]
            for line in text[line_end + 1:].split("\n"):
                if not re.match(r"[ \t]+\[", line):
                    break
                rest += " " + line
        rest = re.split(r"\s#", rest, maxsplit=1)[0]
        synopsis = bool(re.search(r"\[-|\[\.\.\.\]|\(--[^)]*\||\w\|\w|(?:^|\s)\.\.\.(?:\s|$)", rest))
        try:
            tokens = shlex.split(rest)
        except ValueError:  # an apostrophe in a usage line's prose
            tokens = rest.split()
        args = []
        for token in tokens:
            if token in SHELL_STOP or token.startswith((">", "2>")):
                break
            args.append(token)
        found.append((m.group(1), args, inline, synopsis))
    return found


def _parser(module: str):
    mod = importlib.import_module(module)
    if not hasattr(mod, "make_parser"):  # a thin entry point: the parser lives beside its main
        mod = importlib.import_module(mod.entry_point.__module__)
    return mod.make_parser()


def _parse_error(module: str, args: list[str]) -> str | None:
    """None if `args` parse with the module's own parser, else argparse's message."""
    from rtcohand_drake.errors import InputError

    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            _parser(module).parse_args(args)
    except SystemExit as exit_:
        return None if exit_.code == 0 else err.getvalue().strip().splitlines()[-1]  # 0: --help
    except InputError as error:  # run and record report argparse's errors as one line
        return str(error)
    return None


def _excused(message: str, args: list[str], inline: bool) -> bool:
    """A placeholder value (`--camera N`) of a number flag; in prose, a fragment that names some
    flags of a command (`--populations`, without the required ones)."""
    if re.search(r"(?:invalid (?:int|float|_\w+) value|must be a (?:whole )?number, got) '[A-Z][A-Za-z_0-9]*'", message):
        return True
    if inline and "the following arguments are required" in message:
        return True
    return inline and bool(args) and bool(re.search(r"argument %s(?:/\S+)?: expected" % re.escape(args[-1]), message))


def test_quoted_commands_are_found():
    commands = [c for p in QUOTED for c in quoted_commands(p.read_text())]
    assert len(commands) > 60
    joined = next(args for module, args, _, _ in quoted_commands(
        "```bash\npython -m rtcohand_drake.run --a 1 \\\n    --b 2   # note\n```") if module)
    assert joined == ["--a", "1", "--b", "2"]


def test_every_quoted_command_parses():
    """Each `python -m rtcohand_drake...` command in README.md, docs/*.md and models/README.md parses
    with the module's own argument parser (`make_parser()`), as its user would type it."""
    failed = []
    for path in QUOTED:
        for module, args, inline, synopsis in quoted_commands(path.read_text()):
            if module.rsplit(".", 1)[-1].isupper() or synopsis:
                continue
            message = _parse_error(module, args)
            if message is not None and not _excused(message, args, inline):
                failed.append(f"{path.relative_to(REPO)}: python -m {module} {shlex.join(args)}: {message}")
    assert not failed, "\n".join(failed)


# --------------------------------------------------------------------------- results hold no machine paths

# An absolute path (`/srv/checkout/models/...`, `/tmp/soak`, `/home/me/...`) at the start of a word, a
# quoted string or a value; a URL's `//host/` is not one.
ABSOLUTE_PATH = re.compile(r"""(?:^|(?<=[\s"'(=:,\[]))/(?!/)[\w.+-]+/[^\s"',)\]]*""", re.M)
TEXT_SUFFIXES = {".json", ".md", ".txt", ".csv", ".yaml", ".yml", ".log", ".tsv"}


def test_results_hold_no_absolute_paths():
    """Files under docs/results/ are committed and read elsewhere: a path in them is relative to the
    repository (rtcohand_drake.repo_paths), never the checkout's own place on a machine."""
    found = []
    for path in sorted((REPO / "docs" / "results").rglob("*")):
        if path.is_file() and path.suffix in TEXT_SUFFIXES:
            for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
                found += [f"{path.relative_to(REPO)}:{number}: {m.group(0)}" for m in ABSOLUTE_PATH.finditer(line)]
    assert not found, "\n".join(found[:20]) + (f"\n... and {len(found) - 20} more" if len(found) > 20 else "")
    assert ABSOLUTE_PATH.search('"log": "/srv/checkout/out/x.h5"') and ABSOLUTE_PATH.search("rootdir: /tmp/soak")
    assert not ABSOLUTE_PATH.search("see http://localhost:7000/x and models/cchp_default.pt, 0.5 m/s")
