"""The documentation's code runs and its links lead somewhere.

Every ```python block in README.md and docs/*.md is executed on its own: a
fresh interpreter, a temporary working directory, the repository root first on
the import path, SLAM2D_DATA as the environment gives it. A block that raises
fails the test, which names its file and line (the traceback's line numbers are
the Markdown file's). Blocks marked ```bash, ```yaml and so on are not run, but
every block must say what it is, so that no Python hides in an unmarked one.
Every relative link must point to an existing file, and a #fragment to a
heading of that file.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path
from urllib.parse import unquote

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
TIMEOUT_S = 300

_FENCE = re.compile(r"^(?P<indent>[ \t]*)(?P<fence>`{3,}|~{3,})(?P<info>[^`]*)$")

# Runs one block: compiled under the Markdown file's name, padded so that line numbers match it.
_RUNNER = """
import sys
source, name = sys.argv[1], sys.argv[2]
with open(source, encoding="utf-8") as f:
    code = f.read()
exec(compile(code, name, "exec"), {"__name__": "__main__"})
"""


def fenced_blocks(path: Path) -> list[tuple[int, str, str]]:
    """(line of the opening fence, info string, code) of every fenced block of a Markdown file."""
    blocks = []
    lines = path.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, fence, info = m["indent"], m["fence"], m["info"].strip()
        start, body = i + 1, []
        i += 1
        while i < len(lines):
            stripped = lines[i].strip()
            if stripped.startswith(fence) and set(stripped) == {fence[0]}:
                break
            body.append(lines[i][len(indent):] if lines[i].startswith(indent) else lines[i].lstrip())
            i += 1
        i += 1
        blocks.append((start, info, "\n".join(body) + "\n"))
    return blocks


def _where(path: Path, line: int) -> str:
    return f"{path.relative_to(ROOT)}:{line}"


ALL_BLOCKS = [(path, line, info, code) for path in DOCS for line, info, code in fenced_blocks(path)]
PYTHON = [(path, line, code) for path, line, info, code in ALL_BLOCKS if info.split()[:1] == ["python"]]


def test_the_documentation_has_python_blocks():
    assert PYTHON, "no ```python block found in README.md or docs/*.md"


def test_every_block_says_what_it_is():
    bare = [_where(path, line) for path, line, info, _ in ALL_BLOCKS if not info]
    assert not bare, f"fenced blocks without a language (```bash, ```python, ```yaml ...): {', '.join(bare)}"


@pytest.mark.parametrize("path, line, code", PYTHON, ids=[_where(p, n) for p, n, _ in PYTHON])
def test_python_block_runs(path, line, code, tmp_path):
    where = _where(path, line)
    source = tmp_path / "block.py"
    source.write_text("\n" * line + code, encoding="utf-8")  # the block's first line is line + 1
    env = dict(os.environ, MPLBACKEND="Agg")
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    work = tmp_path / "cwd"
    work.mkdir()
    try:
        done = subprocess.run([sys.executable, "-c", _RUNNER, str(source), str(path.relative_to(ROOT))],
                              cwd=work, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the python block at {where} ran longer than {TIMEOUT_S} s", pytrace=False)
    if done.returncode != 0:
        tail = "\n".join((done.stdout + done.stderr).splitlines()[-40:])
        pytest.fail(f"the python block at {where} failed (exit {done.returncode}):\n{tail}", pytrace=False)


# Links: [text](target) outside code; images too. Absolute URLs and mail are not checked.
_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_CODE_SPAN = re.compile(r"`+[^`]*`+")


def _prose(path: Path, code_spans: bool = False) -> list[tuple[int, str]]:
    """(line number, text) of the lines outside fenced blocks; code spans removed unless asked for."""
    out, fence = [], None
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        m = _FENCE.match(line)
        if m and fence is None:
            fence = m["fence"]
            continue
        if fence is not None:
            if line.strip().startswith(fence) and set(line.strip()) == {fence[0]}:
                fence = None
            continue
        out.append((n, line if code_spans else _CODE_SPAN.sub("", line)))
    return out


def anchors(path: Path) -> set[str]:
    """GitHub's anchors of a Markdown file's headings (a repeated one gets -1, -2, ...)."""
    seen: dict[str, int] = {}
    out = set()
    for _, line in _prose(path, code_spans=True):
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", m[1])  # a link in a heading: its text
        slug = re.sub(r"[^\w\- ]", "", text.lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


LINKS = [
    (path, n, target)
    for path in DOCS
    for n, text in _prose(path)
    for target in _LINK.findall(text)
    if not re.match(r"^[a-z][a-z0-9+.-]*:", target)  # http:, https:, mailto:
]


def test_the_documentation_has_links():
    assert LINKS


@pytest.mark.parametrize("path, line, target", LINKS, ids=[f"{_where(p, n)}:{t}" for p, n, t in LINKS])
def test_relative_link_resolves(path, line, target):
    file_part, _, fragment = target.partition("#")
    dest = (path.parent / unquote(file_part)).resolve() if file_part else path
    assert dest.exists(), f"{_where(path, line)}: {target} -> no such file {dest}"
    if fragment:
        assert dest.suffix == ".md", f"{_where(path, line)}: {target}: a fragment on a file that is not Markdown"
        assert unquote(fragment) in anchors(dest), (
            f"{_where(path, line)}: {target}: no heading with anchor #{fragment} in {dest.relative_to(ROOT)}"
        )
