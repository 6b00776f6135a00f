"""The tutorials do what they say: each page's files (fenced blocks with `title="FILE"`) are written
and its tested shell sessions (fenced `console` blocks after a `<!-- test -->` line) are run, in the
page's order, in a fresh directory with the venv's `gyrobench` on PATH; every command must exit 0
and print the lines the page shows under it, in order (`...` stands for any text, runs of spaces
match any run of spaces)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TUTORIALS = sorted((ROOT / "docs" / "tutorials").glob("*.md"))
TUTORIALS = [p for p in TUTORIALS if p.name != "index.md"]
FENCE = re.compile(r"^```(\w+)?(.*)$")
TITLE = re.compile(r'title="([^"]+)"')


@dataclass
class Block:
    """One fenced block of a page: a file to write, or a shell session to run."""

    kind: str  # "file" or "console"
    body: str
    title: str = ""


def blocks(page: Path) -> list[Block]:
    """The page's files and tested console sessions, in order."""
    out: list[Block] = []
    lines = page.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if m and m.group(1):
            lang, info = m.group(1), m.group(2)
            tested = i > 0 and lines[i - 1].strip() == "<!-- test -->"
            j = i + 1
            while not lines[j].startswith("```"):
                j += 1
            body = "\n".join(lines[i + 1: j]) + "\n"
            title = TITLE.search(info)
            if title:
                out.append(Block("file", body, title.group(1)))
            elif lang == "console" and tested:
                out.append(Block("console", body))
            i = j
        i += 1
    return out


def commands(session: str) -> list[tuple[str, list[str]]]:
    """(command, expected output lines) of a console session; `\\` continues a command."""
    out: list[tuple[str, list[str]]] = []
    lines = session.splitlines()
    k = 0
    while k < len(lines):
        line = lines[k]
        if line.startswith("$ "):
            cmd = line[2:]
            while cmd.endswith("\\"):
                k += 1
                cmd = cmd[:-1] + " " + lines[k].strip()
            out.append((cmd, []))
        elif line.strip() and line.strip() != "..." and out:
            out[-1][1].append(line)
        k += 1
    return out


def pattern(expected: str) -> re.Pattern:
    """An expected line as a regex: `...` any text, a run of spaces any run of spaces."""
    parts = [r"\s+".join(re.escape(word) for word in part.split()) for part in expected.strip().split("...")]
    return re.compile(".*".join(parts))


def check_output(cmd: str, output: str, expected: list[str]) -> None:
    got = [" ".join(line.split()) for line in output.splitlines()]
    at = 0
    for want in expected:
        rx = pattern(want)
        while at < len(got) and not rx.search(got[at]):
            at += 1
        assert at < len(got), f"`{cmd}` did not print (in order) {want!r}; it printed:\n{output}"
        at += 1


def test_the_tutorial_pages_have_tested_sessions():
    assert len(TUTORIALS) >= 4
    for page in TUTORIALS:
        assert any(b.kind == "console" for b in blocks(page)), f"{page.name} has no tested console block"


def test_the_pattern_rule():
    check_output("x", "run 2026-ab  hrg-damping  COMPLETE\nreport runs/a.html\n",
                 ["run ... hrg-damping COMPLETE", "report runs/...html"])
    with pytest.raises(AssertionError):
        check_output("x", "report runs/a.html\nrun 1 hrg-damping COMPLETE\n", ["run ...", "report ..."])


@pytest.mark.parametrize("page", TUTORIALS, ids=[p.stem for p in TUTORIALS])
def test_tutorial_commands_run_as_shown(page, tmp_path):
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    env.pop("PYTEST_ADDOPTS", None)
    env.pop("PYTEST_CURRENT_TEST", None)
    for block in blocks(page):
        if block.kind == "file":
            target = tmp_path / block.title
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(block.body, encoding="utf-8")
            continue
        for cmd, expected in commands(block.body):
            run = subprocess.run(["bash", "-c", cmd], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, text=True, timeout=240, stdin=subprocess.DEVNULL)
            output = run.stdout
            assert run.returncode == 0, f"{page.name}: `{cmd}` exited {run.returncode}:\n{output}"
            check_output(cmd, output, expected)


def test_the_readme_pytest_snippet_runs(tmp_path):
    """The README's example test (the pytest plugin's fixtures) passes as written."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    snippet = text.split("```python\n", 1)[1].split("```", 1)[0]
    (tmp_path / "test_spin.py").write_text(snippet, encoding="utf-8")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    env.pop("PYTEST_ADDOPTS", None)
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_spin.py"],
                         cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         timeout=240)
    assert run.returncode == 0 and "1 passed" in run.stdout, run.stdout
