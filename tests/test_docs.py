"""The README and docs/ stay true: every relative link resolves (anchors too), every command shown is real.

Commands are found in shell code blocks and inline code: a `robogest SUBCOMMAND ...` (also after `python -m` or
`torchrun ... -m`) must name real subcommands and only flags of the matching argparse subparser, and a
`make TARGET` a target of the Makefile.
"""

from __future__ import annotations

import argparse
import re
import shlex
from collections.abc import Iterator
from pathlib import Path

import pytest

from robogest.cli.main import build_parser

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
SHELL_LANGS = {"", "sh", "bash", "shell", "console"}

_FENCE = re.compile(r"^\s*(```+|~~~+)\s*([\w+-]*)")
_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_INLINE = re.compile(r"(`+)(.+?)\1")


def _blocks(text: str) -> Iterator[tuple[str | None, str]]:
    """(language, text) of each fenced code block, and (None, text) of each run of prose lines."""
    lang: str | None = None
    buf: list[str] = []
    for line in text.splitlines():
        m = _FENCE.match(line)
        if m and lang is None:
            yield None, "\n".join(buf)
            lang, buf = m.group(2).lower(), []
        elif m and line.strip().startswith(("```", "~~~")) and not m.group(2):
            yield lang, "\n".join(buf)
            lang, buf = None, []
        else:
            buf.append(line)
    yield lang, "\n".join(buf)


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped (not `-`/`_`), spaces to `-`."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a Markdown file (duplicates get GitHub's `-1`, `-2` suffixes)."""
    seen: dict[str, int] = {}
    out: set[str] = set()
    for lang, text in _blocks(path.read_text(encoding="utf-8")):
        if lang is not None:
            continue
        for line in text.splitlines():
            m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
            if not m:
                continue
            s = slug(m.group(1))
            n = seen.get(s, 0)
            seen[s] = n + 1
            out.add(s if n == 0 else f"{s}-{n}")
    return out


def link_problems(page: Path) -> list[str]:
    problems = []
    for lang, text in _blocks(page.read_text(encoding="utf-8")):
        if lang is not None:
            continue
        text = _INLINE.sub("", text)
        for target in _LINK.findall(text):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
                continue
            path_part, _, anchor = target.partition("#")
            dest = (page.parent / path_part).resolve() if path_part else page
            where = f"{page.name}: link {target!r}"
            if not dest.exists():
                problems.append(f"{where}: no file {dest}")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                problems.append(f"{where}: no heading with anchor #{anchor} in {dest.name}")
    return problems


def commands(text: str) -> Iterator[list[str]]:
    """Token lists of the shell commands in a page's shell code blocks and inline code spans."""
    snippets: list[str] = []
    for lang, block in _blocks(text):
        if lang is None:
            snippets += [m.group(2) for m in _INLINE.finditer(block)]
        elif lang in SHELL_LANGS:
            snippets += block.replace("\\\n", " ").splitlines()
    for snippet in snippets:
        snippet = re.sub(r"(^|\s)#.*$", "", snippet)  # a comment
        for part in re.split(r"\s*(?:;|&&|\|\||\||&)\s*", snippet):
            part = re.sub(r"^\$\s+", "", part.strip())
            try:
                tokens = shlex.split(part)
            except ValueError:  # an unbalanced quote in prose
                tokens = part.split()
            if tokens:
                yield tokens


def _robogest_args(tokens: list[str]) -> list[str] | None:
    """The arguments after `robogest` when this is a robogest command line, else None."""
    first = tokens[0].rsplit("/", 1)[-1]
    if first == "robogest":
        return tokens[1:]
    if first in {"python", "python3", "torchrun"} and "-m" in tokens:
        i = tokens.index("-m")
        if i + 1 < len(tokens) and tokens[i + 1] == "robogest":
            return tokens[i + 2 :]
    return None


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def cli_problems(args: list[str], parser: argparse.ArgumentParser) -> list[str]:
    """What in `robogest ARGS` the CLI does not have: an unknown subcommand or a flag of no such name."""
    path = ["robogest"]
    i = 0
    while (subs := _subparsers(parser)) and i < len(args) and not args[i].startswith("-"):
        if args[i] not in subs:
            return [f"{' '.join(path)}: no subcommand {args[i]!r} (has {', '.join(sorted(subs))})"]
        parser = subs[args[i]]
        path.append(args[i])
        i += 1
    if len(path) == 1 and i < len(args) and args[i] != "..." and not args[i].startswith("-"):
        return [f"robogest: no subcommand {args[i]!r}"]
    known = set(parser._option_string_actions)
    problems = []
    for arg in args[i:]:
        flag = arg.strip("[]").split("=", 1)[0]
        if not flag.startswith("-") or flag in {"-", "--"} or re.match(r"^-[\d.]", flag):
            continue
        if flag not in known:
            problems.append(f"{' '.join(path)}: no flag {flag}")
    return problems


def make_targets() -> set[str]:
    text = (REPO / "Makefile").read_text(encoding="utf-8")
    return {m.group(1) for m in re.finditer(r"^([A-Za-z0-9_-]+)\s*:(?!=)", text, re.MULTILINE)}


def command_problems(text: str, parser: argparse.ArgumentParser, targets: set[str]) -> tuple[list[str], int]:
    """Problems in every command of a page's text, and how many commands were checked."""
    problems: list[str] = []
    n = 0
    for tokens in commands(text):
        args = _robogest_args(tokens)
        if args is not None:
            n += 1
            problems += [f"`{shlex.join(tokens)}`: {p}" for p in cli_problems(args, parser)]
        elif tokens[0] == "make":
            n += 1
            for t in tokens[1:]:
                if not t.startswith("-") and "=" not in t and t not in targets:
                    problems.append(f"`{shlex.join(tokens)}`: no Makefile target {t!r}")
    return problems, n


@pytest.fixture(scope="module")
def parser() -> argparse.ArgumentParser:
    return build_parser()


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_relative_links_resolve(page: Path) -> None:
    assert link_problems(page) == []


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_commands_are_real(page: Path, parser: argparse.ArgumentParser) -> None:
    problems, _ = command_problems(page.read_text(encoding="utf-8"), parser, make_targets())
    assert problems == []


def test_readme_is_short_and_links_every_page() -> None:
    """The README stays an overview (details go to docs/) and its reader can reach every docs page."""
    text = PAGES[0].read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 250, "README.md: over 250 lines; move details to a page in docs/"
    linked = {Path(t.partition("#")[0]).name for t in _LINK.findall(text) if t.startswith("docs/")}
    unlinked = [p.name for p in PAGES[1:] if p.name not in linked]
    assert unlinked == [], "README.md: add these pages to 'Where to read next'"


@pytest.mark.parametrize("page", PAGES[1:], ids=lambda p: p.name)
def test_docs_page_links_back_to_readme(page: Path) -> None:
    """Each page opens with its title, then a one-line summary; the page links back to the README."""
    text = page.read_text(encoding="utf-8")
    assert text.startswith("# "), f"{page.name}: start with a '# Title' line, then a one-line summary"
    assert "](../README.md)" in text, f"{page.name}: add [Back to the README](../README.md) to its summary line"


def test_pages_show_commands(parser: argparse.ArgumentParser) -> None:
    """The checker finds the commands (it would pass vacuously if it found none)."""
    total = sum(command_problems(p.read_text(encoding="utf-8"), parser, make_targets())[1] for p in PAGES)
    assert total >= 50


def test_checker_catches_made_up_commands(parser: argparse.ArgumentParser, tmp_path: Path) -> None:
    text = (
        "```sh\nrobogest speak 'Hi' --no-such-flag 3   # comment --ignored\n"
        "robogest servo scann --port /dev/ttyUSB0\n"
        "torchrun --nproc_per_node 2 -m robogest train --model s2ag --epoch 3\nmake tests\n```\n"
        "Inline: `robogest robots show NAME --jsn`, fine: `robogest servo scan --robot R [--all]`.\n"
    )
    problems, n = command_problems(text, parser, make_targets())
    assert n == 6
    assert len(problems) == 5
    for bad in ("no flag --no-such-flag", "no subcommand 'scann'", "no flag --epoch", "'tests'", "no flag --jsn"):
        assert any(bad in p for p in problems), bad


def test_checker_catches_broken_links(tmp_path: Path) -> None:
    (tmp_path / "a.md").write_text("# A page\n\n## Some `code`: here\n", encoding="utf-8")
    page = tmp_path / "b.md"
    page.write_text("[ok](a.md#some-code-here) [bad](a.md#nope) [gone](c.md) `[code](x.md)`\n", encoding="utf-8")
    problems = link_problems(page)
    assert len(problems) == 2
    assert "#nope" in problems[0] and "c.md" in problems[1]


def test_slug_is_githubs() -> None:
    assert slug("A live robot: Python API and `robogest serve`") == "a-live-robot-python-api-and-robogest-serve"
    assert slug("Playback at any rate, jerk, go-to-rest, signals") == "playback-at-any-rate-jerk-go-to-rest-signals"
