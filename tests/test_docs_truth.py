"""Docs that cannot drift (issue 46): the flags docs/cli.md names are the program's, read from its own argument
parser (so a verb or flag added later must be documented), the JSON keys the docs list are the output's, every
page is listed in docs/index.md and in mkdocs.yml's nav, and reference pages hold no change log."""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import pytest

from solvers.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
CLI_MD = DOCS / "cli.md"
FLAG = re.compile(r"(?<![\w-])(--?[A-Za-z][\w-]*)")
OTHER_PROGRAMS = ("scripts/", "pip install", "dask worker", "msolve -")
"""A line naming one of these is about another program, whose flags are not tdoa-workbench's."""


def verbs() -> dict[str, argparse.ArgumentParser]:
    """Every verb of the command line, from the parser itself."""
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def options(parser: argparse.ArgumentParser) -> list[tuple[str, ...]]:
    """The option strings of each optional argument of a parser (help left out)."""
    return [tuple(a.option_strings) for a in parser._actions
            if a.option_strings and not isinstance(a, argparse._HelpAction)]


def synopsis() -> dict[str, set[str]]:
    """verb -> the flags its lines in cli.md's synopsis name (a line starting 'tdoa-workbench VERB', and the
    indented lines after it)."""
    text = CLI_MD.read_text(encoding="utf-8")
    block = text[text.index("## Synopsis"):]
    block = block[block.index("```\n") + 4:]
    block = block[:block.index("```")]
    out: dict[str, set[str]] = {}
    verb = None
    for line in block.splitlines():
        start = re.match(r"tdoa-workbench (\S+)", line)
        if start:
            verb = start.group(1)
            rest = line[start.end():]
        else:
            assert line.startswith(" ") and verb, f"synopsis line outside a verb: {line!r}"
            rest = line
        out.setdefault(verb, set()).update(FLAG.findall(rest))
    return out


def test_every_flag_of_every_verb_is_in_the_synopsis():
    documented = synopsis()
    parsers = verbs()
    assert set(parsers) <= set(documented), f"verbs missing from docs/cli.md's synopsis: {set(parsers) - set(documented)}"
    missing = {verb: [s[-1] for s in options(p) if not set(s) & documented[verb]] for verb, p in parsers.items()}
    missing = {v: m for v, m in missing.items() if m}
    assert not missing, f"flags of --help missing from docs/cli.md's synopsis: {missing}"
    foreign = {verb: sorted(flags - {o for s in options(parsers[verb]) for o in s})
               for verb, flags in documented.items() if verb in parsers}
    foreign = {v: f for v, f in foreign.items() if f}
    assert not foreign, f"docs/cli.md's synopsis names flags the verb does not have: {foreign}"


def test_every_flag_cli_md_names_exists():
    known = {o for p in verbs().values() for s in options(p) for o in s} | {"--version", "--help", "-h"}
    named = {}
    for n, line in enumerate(CLI_MD.read_text(encoding="utf-8").splitlines(), 1):
        if any(other in line for other in OTHER_PROGRAMS):
            continue
        for flag in FLAG.findall(line):
            if flag.startswith("--"):
                named.setdefault(flag, n)
    unknown = {flag: f"line {n}" for flag, n in named.items() if flag not in known}
    assert not unknown, f"docs/cli.md names flags no verb has: {unknown}"


def test_the_flag_tests_see_a_stale_synopsis(monkeypatch):
    """Not vacuous: a verb with a flag the synopsis lacks fails the first test."""
    real = build_parser

    def with_new_flag():
        parser = real()
        action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        action.choices["degree"].add_argument("--undocumented-flag")
        return parser

    monkeypatch.setattr(sys.modules[__name__], "build_parser", with_new_flag)
    with pytest.raises(AssertionError, match="undocumented-flag"):
        test_every_flag_of_every_verb_is_in_the_synopsis()


def documented_keys(page: Path, name: str) -> set[str]:
    """The JSON keys in the first column of the table after the marker ``<!-- json keys: NAME -->``."""
    lines = page.read_text(encoding="utf-8").splitlines()
    k = lines.index(f"<!-- json keys: {name} -->") + 3  # the marker, the header, the rule
    keys: set[str] = set()
    while k < len(lines) and lines[k].startswith("|"):
        keys.update(re.findall(r"`([a-z_]+)`", lines[k].split("|")[1]))
        k += 1
    assert keys, f"{page.name}: no keys after the json keys marker {name!r}"
    return keys


def _json(capsys, *argv, codes=(0,)) -> dict:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code in codes, err
    return json.loads(out)


def test_degree_json_keys_are_the_documented_ones(capsys):
    from analysis.engine.msolve import find_msolve

    documented = documented_keys(CLI_MD, "degree")
    katsura = ROOT / "examples" / "katsura4.ms"
    runs = [_json(capsys, "degree", katsura, "--json", "--basis", "--gb"),
            _json(capsys, "degree", ROOT / "examples" / "circle.sys", "--json"),
            _json(capsys, "degree", "--tdoa", "6r4s", "--equations", "C2-C6", "--json"),
            _json(capsys, "degree", "--tdoa", "6r4s", "--equations", "B2,C2-C6,minors", "--json")]
    msolve_keys = {"engines", "check"}
    if find_msolve() is not None:
        runs.append(_json(capsys, "degree", katsura, "--json", "--engine", "msolve"))
    else:
        documented -= msolve_keys
    for run in runs:
        assert set(run) <= documented, f"degree --json keys not in docs/cli.md's table: {set(run) - documented}"
    seen = set().union(*map(set, runs))
    assert documented <= seen, f"docs/cli.md documents degree --json keys no run printed: {documented - seen}"


def test_calibrate_json_keys_are_the_documented_ones(capsys, tmp_path):
    import numpy as np

    from solvers.synthetic import random_network

    F = random_network(6, 4, np.random.default_rng(0)).measurements()
    path = tmp_path / "network.csv"
    path.write_text("\n".join(",".join(f"{v:.6f}" for v in row) for row in F) + "\n")
    report = _json(capsys, "calibrate", path, "--json", "--sigma", "0.01", codes=(0, 1))  # any status: the keys
    documented = documented_keys(DOCS / "calibrate.md", "calibrate")
    assert set(report) == documented, (f"calibrate --json keys: undocumented {set(report) - documented}, documented "
                                       f"but missing {documented - set(report)}")


def pages() -> list[Path]:
    return sorted(DOCS.rglob("*.md"))


def test_the_index_lists_every_page():
    """docs/index.md links every page (the findings through findings/index.md, which links each of them)."""
    def links(page: Path) -> set[Path]:
        text = page.read_text(encoding="utf-8")
        return {(page.parent / target.split("#")[0]).resolve()
                for target in re.findall(r"\]\(([^)]+\.md)(?:#[^)]*)?\)", text)}

    home, findings = DOCS / "index.md", DOCS / "findings" / "index.md"
    listed = links(home) | (links(findings) if findings.resolve() in links(home) else set())
    missing = [str(p.relative_to(DOCS)) for p in pages() if p not in (home,) and p.resolve() not in listed]
    assert not missing, f"pages docs/index.md does not list: {missing}"


def test_the_mkdocs_nav_lists_every_page():
    nav = set(re.findall(r"^\s*-\s+(?:[^:\n]+:\s+)?(\S+\.md)\s*$", (ROOT / "mkdocs.yml").read_text(encoding="utf-8"),
                         re.MULTILINE))
    missing = [str(p.relative_to(DOCS)) for p in pages() if str(p.relative_to(DOCS)) not in nav]
    assert not missing, f"pages mkdocs.yml's nav does not list: {missing}"
    stale = sorted(n for n in nav if not (DOCS / n).is_file())
    assert not stale, f"mkdocs.yml's nav lists missing pages: {stale}"


CHANGE_LOG = re.compile(r"what changed|in this round|before this change", re.IGNORECASE)


def test_reference_pages_hold_no_change_log():
    """A change log belongs under docs/findings/ (or in git log); the other pages say what is."""
    found = [f"{p.relative_to(ROOT)}:{n}" for p in [ROOT / "README.md", *pages()] if "findings" not in p.parts
             for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if CHANGE_LOG.search(line)]
    assert not found, f"change-log text on reference pages (move it under docs/findings/): {found}"
