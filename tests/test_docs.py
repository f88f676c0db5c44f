"""The docs name only what exists: every repository path a page names in code (`gaitlib/meta/guard.py`), and every
``--flag`` a ``gaitlib COMMAND`` in a page passes, is checked against the checkout and the ``gaitlib`` app itself; and
``docs/cli.md`` is what ``python -m benchmarks.cli_doc`` makes of the app."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
import typer

from benchmarks import cli_doc

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").glob("*.md"), *ROOT.glob("library*/README.md")])
TRACKED = set(subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split())
"""Every file git tracks, and (below) every folder holding one: what a fresh clone has."""
FOLDERS = {str(Path(f).parents[i]) for f in TRACKED for i in range(len(Path(f).parents) - 1)}
TOP = {Path(f).parts[0] for f in TRACKED}
"""The repository's top-level names: a path whose first part is one of them is a repository path."""
GENERATED = ("data/", "runs/", "gaitlib/library/shipped/")
"""Made at run time or by the build, never in git: a page may name what a command writes there."""
PLACEHOLDER = re.compile(r"(?<![A-Za-z])(?!README|CHANGELOG|LICENSE|MANIFEST)[A-Z][A-Z0-9_]+(?![a-z])|[*<>{}$]|\.\.\.")
"""A path with a placeholder (``eval-GAIT.json``, ``runs/routes-<12 hex>``, ``*.json``) names a family, not a file."""
CODE_SPAN = re.compile(r"`([^`\n]+)`")
FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.S | re.M)
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
NOT_YET = re.compile(r"Not yet measured: .*? not stored yet\.", re.S)
"""A generated table's sentence naming the evidence a measurement is still to store (``benchmarks.results``)."""


def _code(text: str) -> list[str]:
    """The code a page holds: its fenced blocks' lines (a trailing ``\\`` joined to the next) and its inline spans."""
    blocks = [re.sub(r"\\\n\s*", " ", block) for block in FENCE.findall(text)]
    prose = FENCE.sub("", text)
    return [line for block in blocks for line in block.splitlines()] + CODE_SPAN.findall(prose.replace("\\|", "|"))


def _is_path(token: str) -> bool:
    token = token.rstrip(".,:;")
    if "/" not in token or "://" in token or PLACEHOLDER.search(token) or token.startswith(GENERATED):
        return False
    return token.split("/")[0] in TOP


def named_paths(text: str, page: Path) -> set[str]:
    """The repository paths ``text`` (the page ``page``) names: in code, and as relative links; not the evidence a
    table's "Not yet measured" sentence names, which its measurement is still to store."""
    found, text = set(), NOT_YET.sub("", text)
    for code in _code(text):
        for token in re.split(r"[\s=\"'(),\[\]]+", code):
            if _is_path(token):
                found.add(token.rstrip(".,:;").rstrip("/"))
    for target in LINK.findall(text):
        if "://" not in target and not target.startswith("mailto:"):
            found.add(str((page.parent / target).resolve().relative_to(ROOT)))
    return found


def _exists(path: str) -> bool:
    return path in TRACKED or path in FOLDERS or ((ROOT / path).exists() and not path.startswith(GENERATED))


def _app():
    from gaitlib.cli import app

    return typer.main.get_command(app)


def _options(command) -> set[str]:
    return {o for p in command.params if p.param_type_name == "option" for o in [*p.opts, *p.secondary_opts]}


def unknown_flags(text: str, app=None) -> list[str]:
    """Each ``gaitlib COMMAND ... --flag`` in the code of ``text`` whose flag the app's command does not have."""
    app = app or _app()
    wrong = []
    for code in _code(text):
        for segment in re.split(r"&&|;|\|\||\s#\s", code):
            tokens = segment.replace("`", " ").split()
            starts = [i for i, token in enumerate(tokens) if token.lstrip("(") in ("gaitlib", ".venv/bin/gaitlib")]
            ends = [*starts[1:], len(tokens)] if starts else []
            for start, end in zip(starts, ends, strict=True):
                command, used, rest = app, [], tokens[start + 1:end]
                while rest and hasattr(command, "commands") and rest[0] in command.commands:
                    command, used, rest = command.commands[rest[0]], [*used, rest[0]], rest[1:]
                known = _options(command) | {"--help"}
                for flag in re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", " ".join(rest)):
                    if flag not in known:
                        wrong.append(" ".join(["gaitlib", *used, flag]))
    return wrong


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_page_names_only_files_that_exist(page: Path) -> None:
    missing = sorted(p for p in named_paths(page.read_text(encoding="utf-8"), page) if not _exists(p))
    assert not missing, f"{page.relative_to(ROOT)} names files the repository lacks: {missing}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_page_passes_only_flags_the_cli_has(page: Path) -> None:
    wrong = sorted(set(unknown_flags(page.read_text(encoding="utf-8"))))
    assert not wrong, f"{page.relative_to(ROOT)} passes options the CLI lacks: {wrong}"


def test_the_checks_catch_a_bogus_flag_a_bogus_command_and_a_missing_file() -> None:
    page = ROOT / "docs" / "example.md"
    text = ("Run `gaitlib run --from trot --bogus-flag 3`, then\n\n```bash\ngaitlib survival fit data/x.h5 \\\n"
            "  --no-such-option\ngaitlib eval trot --episodes 4   # fine\n```\n\nSee `gaitlib/no_such_module.py` and "
            "`docs/switching.md`; `runs/library/metadata.json` is written at run time.\n")
    assert sorted(unknown_flags(text)) == ["gaitlib run --bogus-flag", "gaitlib survival fit --no-such-option"]
    assert sorted(p for p in named_paths(text, page) if not _exists(p)) == ["gaitlib/no_such_module.py"]


def test_a_table_not_yet_measured_names_its_evidence_to_come_but_other_paths_are_checked() -> None:
    page = ROOT / "docs" / "example.md"
    text = ("Not yet measured: `docs/results/timings/a.json`,\n`docs/results/timings/b.json` not stored yet.\n\n"
            "See `docs/results/timings/c.json`.\n")
    assert sorted(named_paths(text, page)) == ["docs/results/timings/c.json"]


def test_the_cli_reference_is_what_the_app_makes() -> None:
    assert cli_doc.CLI_DOC.read_text(encoding="utf-8") == cli_doc.render(), (
        "docs/cli.md differs from the app: python -m benchmarks.cli_doc rewrites it")
