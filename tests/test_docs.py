"""The documentation runs as written: README.md, docs/*.md, benchmarks/README.md and
benchmarks/studies/README.md.

- Every fenced ``python`` block marked ``<!-- test: run -->`` on the line before it runs as a
  script, in a fresh folder (so a missing ``if __name__ == "__main__":`` guard fails).
- Every other ``python`` block compiles, and the names it imports from ``strl_pyg`` exist.
- Every ``strl-pose ...``, ``python examples/*.py ...`` and ``python benchmarks/*.py ...``
  (or ``benchmarks/studies/*.py``) command (fenced shell blocks and inline code) names an
  existing subcommand or script and uses only ``--flags`` that its parser knows:
  ``strl_pyg.cli.commands.build_parser()`` (and ``strl_pyg.evaluation.run.build_parser()`` for
  ``evaluate``), or the script's ``--help``.
- Every relative link points at an existing file, and its ``#anchor`` at a heading there.
- Every dotted ``strl_pyg.x.y`` name and every ``strl_pyg/``, ``examples/``, ``benchmarks/``,
  ``tests/`` or ``docs/`` path in inline code exists.
"""

from __future__ import annotations

import argparse
import ast
import functools
import importlib
import json
import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
DOC_FILES = sorted([REPO_ROOT / "README.md", REPO_ROOT / "benchmarks" / "README.md",
                    REPO_ROOT / "benchmarks" / "studies" / "README.md",
                    *(REPO_ROOT / "docs").glob("*.md")])
RUN_MARKER = "<!-- test: run -->"
SHELL_LANGS = {"bash", "sh", "shell", "console", ""}
#: Deprecated names that a page may mention on purpose (to say that they are deprecated).
DEPRECATED_MENTIONS: dict[str, set[str]] = {}

_FENCE = re.compile(r"^(\s*)(```|~~~)\s*([\w+-]*)")
_INLINE = re.compile(r"`([^`\n]+)`")
_LINK = re.compile(r"(?<!!)\[[^\]\n]*\]\(([^)\s]+)\)|!\[[^\]\n]*\]\(([^)\s]+)\)")
_FLAG = re.compile(r"(?<![\w-])--[A-Za-z][\w-]*")
_SCRIPT = re.compile(r"(?:^|/)((?:examples|benchmarks|benchmarks/studies)/[\w.-]+\.py)$")
#: The folders whose pages may name their own scripts bare (``x.py``).
SCRIPT_FOLDERS = ("examples", "benchmarks", "benchmarks/studies")
_DOTTED = re.compile(r"\bstrl_pyg(?:\.[A-Za-z_]\w*)+")
_PATH = re.compile(r"^(?:strl_pyg|examples|benchmarks|tests|docs)/[\w./-]*[\w-]$")


# ----------------------------------------------------------------------------- parsing
@dataclass
class Block:
    path: Path
    line: int  # 1-based line of the opening fence
    lang: str
    text: str
    run: bool

    @property
    def where(self) -> str:
        return f"{_rel(self.path)}:{self.line}"


@dataclass
class Page:
    path: Path
    blocks: list[Block]
    prose: list[tuple[int, str]]  # (line, text) outside fenced blocks


def parse_markdown(path: Path, text: str | None = None) -> Page:
    """Fenced blocks (with their language and run marker) and the lines outside them."""
    lines = (path.read_text() if text is None else text).splitlines()
    blocks, prose = [], []
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            prose.append((i + 1, lines[i]))
            i += 1
            continue
        fence, lang, start = m.group(2), m.group(3).lower(), i
        body = []
        i += 1
        while i < len(lines) and not lines[i].strip().startswith(fence):
            body.append(lines[i])
            i += 1
        i += 1  # the closing fence
        before = next((lines[j].strip() for j in range(start - 1, -1, -1) if lines[j].strip()),
                      "")
        blocks.append(Block(path, start + 1, lang, "\n".join(body) + "\n", before == RUN_MARKER))
    return Page(path, blocks, prose)


def inline_spans(page: Page) -> list[tuple[int, str]]:
    return [(n, m.group(1).strip()) for n, line in page.prose for m in _INLINE.finditer(line)]


def _rel(path: Path) -> str:
    try:
        return str(path.relative_to(REPO_ROOT))
    except ValueError:
        return str(path)


PAGES = [parse_markdown(p) for p in DOC_FILES]
BLOCKS = [b for page in PAGES for b in page.blocks]
RUNNABLE = [b for b in BLOCKS if b.run]
PYTHON = [b for b in BLOCKS if b.lang == "python"]


# ----------------------------------------------------------------------------- commands
def shell_lines(text: str) -> list[str]:
    """The command lines of a shell block: continuations joined, comments kept for shlex."""
    return [ln for ln in text.replace("\\\n", " ").splitlines() if ln.strip()]


def segments(line: str) -> list[list[str]]:
    """Simple commands of one shell line (split at ``&&``, ``||``, ``;``, ``|``), comments
    dropped; ``[]`` on unparseable lines."""
    lex = shlex.shlex(line, posix=True, punctuation_chars=";&|")
    lex.whitespace_split = True
    lex.commenters = "#"
    try:
        tokens = list(lex)
    except ValueError:
        return []
    out, cur = [], []
    for tok in tokens:
        if tok and set(tok) <= set(";&|"):
            out.append(cur)
            cur = []
        else:
            cur.append(tok)
    return [s for s in out + [cur] if s]


@dataclass
class Command:
    where: str
    text: str
    program: str  # "strl-pose" or a script path relative to the repository
    subcommand: str | None
    flags: list[str]


def _script(tok: str, page_dir: Path | None) -> str | None:
    """``examples/x.py`` / ``benchmarks/x.py`` / ``benchmarks/studies/x.py`` named by ``tok``;
    on a page inside one of those folders a bare ``x.py`` is that folder's."""
    m = _SCRIPT.search(tok)
    if m:
        return m.group(1)
    folder = _rel(page_dir) if page_dir is not None else None
    if folder in SCRIPT_FOLDERS and re.fullmatch(r"[\w-]+\.py", tok):
        return f"{folder}/{tok}"
    return None


def find_commands(tokens: list[str], where: str, text: str,
                  page_dir: Path | None = None) -> Command | None:
    """The ``strl-pose`` or ``examples/`` / ``benchmarks/`` script command in ``tokens``."""
    for i, tok in enumerate(tokens):
        rest = tokens[i + 1:]
        flags = [f for t in rest for f in _FLAG.findall(t)]
        if tok == "strl-pose" or tok.endswith("/strl-pose"):
            sub = next((t for t in rest if not t.startswith("-")), None)
            return Command(where, text, "strl-pose", sub, flags)
        script = _script(tok, page_dir)
        if script:
            return Command(where, text, script, None, flags)
    return None


def page_commands(page: Page) -> list[Command]:
    found = []
    for b in page.blocks:
        if b.lang not in SHELL_LANGS:
            continue
        for k, line in enumerate(shell_lines(b.text)):
            for seg in segments(line):
                cmd = find_commands(seg, f"{b.where} (line {k + 1} of the block)", line,
                                    page.path.parent)
                if cmd:
                    found.append(cmd)
    for n, span in inline_spans(page):
        first = span.split()[0] if span.split() else ""
        if not (first.endswith("strl-pose") or "python" in Path(first).name
                or _script(first, page.path.parent)):
            continue  # only spans that start with the command
        for seg in segments(span):
            cmd = find_commands(seg, f"{_rel(page.path)}:{n} (inline)", span, page.path.parent)
            if cmd:
                found.append(cmd)
    return found


@functools.cache
def strl_pose_flags() -> dict[str | None, set[str]]:
    """``{subcommand: option strings}`` of ``strl-pose``; ``None``: the top-level parser."""
    from strl_pyg.cli.commands import build_parser

    def options(p: argparse.ArgumentParser) -> set[str]:
        return {s for a in p._actions for s in a.option_strings}

    ap = build_parser()
    table: dict[str | None, set[str]] = {None: options(ap)}
    for action in ap._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                table[name] = options(sub)
    from strl_pyg.evaluation.run import build_parser as evaluate_parser

    table["evaluate"] = options(evaluate_parser(prog="strl-pose evaluate"))
    return table


def script_flags(script: str, script_help) -> frozenset[str]:
    """The ``--flags`` in ``python SCRIPT --help`` (the root conftest's ``script_help``)."""
    code, stdout, stderr = script_help([REPO_ROOT / script])[REPO_ROOT / script]
    assert code == 0, f"{script} --help failed: {stderr[-1500:]}"
    return frozenset(_FLAG.findall(stdout))


def command_errors(cmd: Command, script_help) -> list[str]:
    bad = []
    if cmd.program == "strl-pose":
        table = strl_pose_flags()
        sub = cmd.subcommand
        if sub is not None and sub not in table:
            return [f"{cmd.where}: unknown subcommand 'strl-pose {sub}' in: {cmd.text}"]
        known = table[sub]
        name = f"strl-pose {sub}" if sub else "strl-pose"
    else:
        if not (REPO_ROOT / cmd.program).is_file():
            return [f"{cmd.where}: no script {cmd.program} in: {cmd.text}"]
        if not cmd.flags:
            return []
        known = script_flags(cmd.program, script_help)
        name = cmd.program
    for flag in cmd.flags:
        if flag not in known:
            bad.append(f"{cmd.where}: {name} has no flag {flag} (known: "
                       f"{', '.join(sorted(known))}) in: {cmd.text}")
    return bad


# ----------------------------------------------------------------------------- links
def github_slug(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # links: their text
    text = re.sub(r"[^\w\- ]", "", text.strip().lower())
    return text.replace(" ", "-")


@functools.cache
def anchors(path: Path) -> frozenset[str]:
    seen: dict[str, int] = {}
    out = set()
    for _, line in parse_markdown(path).prose:
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        slug = github_slug(m.group(1))
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return frozenset(out)


def link_errors(page: Page) -> list[str]:
    bad = []
    for n, line in page.prose:
        line = _INLINE.sub("", line)  # links inside inline code are not links
        for m in _LINK.finditer(line):
            target = m.group(1) or m.group(2)
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
                continue
            file_part, _, anchor = target.partition("#")
            dest = (page.path.parent / file_part).resolve() if file_part else page.path
            where = f"{_rel(page.path)}:{n}"
            if not dest.exists():
                bad.append(f"{where}: link to a missing file: {target}")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                bad.append(f"{where}: link to a missing heading #{anchor} in {_rel(dest)} "
                           f"(headings: {', '.join(sorted(anchors(dest)))})")
    return bad


# ----------------------------------------------------------------------------- names
def _warns_deprecated(module: object) -> bool:
    """Whether a module warns with ``DeprecationWarning`` when imported (read from its source:
    an import in another test would already have spent the warning)."""
    origin = getattr(module, "__file__", None)
    if not origin or not origin.endswith(".py"):
        return False
    for node in ast.parse(Path(origin).read_text()).body:
        if (isinstance(node, ast.Expr) and isinstance(node.value, ast.Call)
                and getattr(node.value.func, "attr", getattr(node.value.func, "id", "")) == "warn"
                and "DeprecationWarning" in ast.unparse(node.value)):
            return True
    return False


def resolve_dotted(name: str) -> str | None:
    """``None`` when ``strl_pyg.a.b.c`` names a module, or an attribute of one, that is not
    deprecated; else why not."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        modname = ".".join(parts[:k])
        try:
            obj = importlib.import_module(modname)
        except ModuleNotFoundError:
            continue  # an attribute, or a module that does not exist: the parent decides
        if _warns_deprecated(obj):
            return f"{modname} is deprecated"
        for attr in parts[k:]:
            if not hasattr(obj, attr):
                return f"{modname} has no {'.'.join(parts[k:])}"
            obj = getattr(obj, attr)
        return None
    return "no such module"


def python_import_errors(block: Block) -> list[str]:
    try:
        tree = ast.parse(block.text)
    except SyntaxError as err:
        return [f"{block.where}: does not parse: {err}"]
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("strl_pyg"):
            for alias in node.names:
                why = resolve_dotted(f"{node.module}.{alias.name}")
                if why:
                    bad.append(f"{block.where}: from {node.module} import {alias.name}: {why}")
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("strl_pyg"):
                    why = resolve_dotted(alias.name)
                    if why:
                        bad.append(f"{block.where}: import {alias.name}: {why}")
    return bad


# ----------------------------------------------------------------------------- tests
def test_the_pages_have_what_this_test_checks():
    assert (REPO_ROOT / "docs").is_dir() and len(PAGES) >= 5
    assert RUNNABLE, f"no block marked {RUN_MARKER!r}"
    assert any(c.program == "strl-pose" for p in PAGES for c in page_commands(p))


#: Runs blocks one after another in one interpreter (each as ``__main__`` in a folder of its
#: own), so the suite pays torch's import once, not once per block.
_RUNNER = """
import contextlib, io, json, os, runpy, sys, traceback
out = {}
for where, path in json.load(open(sys.argv[1])):
    os.chdir(os.path.dirname(path))
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            runpy.run_path(path, run_name="__main__")
        out[where] = None
    except SystemExit as err:
        out[where] = None if err.code in (0, None) else f"exit code {err.code}"
    except BaseException:
        out[where] = buf.getvalue()[-1500:] + traceback.format_exc()[-3000:]
    registry = sys.modules.get("strl_pyg.inference.registry")
    if registry is not None:  # a block's own methods leave with it
        for name, spec in list(registry.METHODS.items()):
            fn = getattr(spec, "fn", spec)
            home = getattr(fn, "__module__", None) or type(fn).__module__
            if not str(home).startswith("strl_pyg."):
                del registry.METHODS[name]
json.dump(out, open(sys.argv[2], "w"))
"""


def _slow(block: Block) -> bool:
    """A block that trains, or that starts worker processes (``num_workers=`` above 0: each
    re-imports the script, which is where a missing ``if __name__ == "__main__":`` guard
    fails), is in the slow tier and runs in a process of its own."""
    return "train(" in block.text or re.search(r"num_workers\s*=\s*[1-9]", block.text) is not None


@pytest.fixture(scope="module")
def block_runs(tmp_path_factory):
    """``where -> None`` (ran) or the failure, for every runnable block of the fast tier (one
    that trains or starts workers is in the slow tier and runs in its own process)."""
    root = tmp_path_factory.mktemp("blocks")
    plan = []
    for i, block in enumerate(b for b in RUNNABLE if not _slow(b) and b.lang == "python"):
        (root / str(i)).mkdir()
        script = root / str(i) / "snippet.py"
        script.write_text(block.text)
        plan.append((block.where, str(script)))
    (root / "plan.json").write_text(json.dumps(plan))
    (root / "runner.py").write_text(_RUNNER)
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    res = subprocess.run([sys.executable, str(root / "runner.py"), str(root / "plan.json"),
                          str(root / "out.json")], cwd=root, env=env, capture_output=True,
                         text=True, timeout=1200)
    assert res.returncode == 0, f"the block runner failed:\n{res.stderr[-3000:]}"
    return json.loads((root / "out.json").read_text())


@pytest.mark.parametrize("block", [
    pytest.param(b, marks=pytest.mark.slow) if _slow(b) else b for b in RUNNABLE
], ids=[b.where for b in RUNNABLE])  # a block that trains or starts workers: the slow tier
def test_marked_python_block_runs_as_a_script(block, tmp_path, request):
    assert block.lang == "python", f"{block.where}: {RUN_MARKER} before a {block.lang!r} block"
    if not _slow(block):
        failure = request.getfixturevalue("block_runs")[block.where]
        assert failure is None, f"{block.where} failed:\n{failure}"
        return
    script = tmp_path / "snippet.py"
    script.write_text(block.text)
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    res = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, f"{block.where} failed:\n{res.stdout[-1500:]}\n{res.stderr[-3000:]}"


def test_every_python_block_compiles_and_imports_existing_names():
    bad = [e for b in PYTHON for e in python_import_errors(b)]
    assert not bad, "\n".join(bad)


@pytest.mark.slow
def test_every_command_uses_only_flags_its_parser_knows(script_help):
    cmds = [c for page in PAGES for c in page_commands(page)]
    assert len(cmds) >= 10, [c.text for c in cmds]
    script_help([REPO_ROOT / c.program for c in cmds  # every script's --help in one process
                 if c.program != "strl-pose" and c.flags and (REPO_ROOT / c.program).is_file()])
    bad = [e for c in cmds for e in command_errors(c, script_help)]
    assert not bad, "\n".join(bad)


def test_every_relative_link_points_at_an_existing_file_and_heading():
    bad = [e for page in PAGES for e in link_errors(page)]
    assert not bad, "\n".join(bad)


def test_every_link_of_the_benchmark_reports_resolves():
    """The result pages of benchmarks/ and benchmarks/studies/, also those a script writes
    with hand notes embedded (a link of studies/results_pose_recipe/notes.md is read from
    studies/, where the report stands: one pointed one folder too high)."""
    bench = REPO_ROOT / "benchmarks"
    pages = sorted([*bench.glob("*.md"), *(bench / "studies").glob("*.md")])
    assert len(pages) >= 20
    bad = [e for p in pages if p not in DOC_FILES for e in link_errors(parse_markdown(p))]
    assert not bad, "\n".join(bad)


def test_every_named_module_attribute_and_path_exists():
    bad = []
    for page in PAGES:
        if _rel(page.path) == "docs/changelog.md":
            continue  # it names what was removed
        allowed = DEPRECATED_MENTIONS.get(_rel(page.path), set())
        texts = inline_spans(page) + [(b.line, b.text) for b in page.blocks
                                      if b.lang not in SHELL_LANGS]
        for n, text in texts:
            for name in set(_DOTTED.findall(text)):
                why = None if name in allowed else resolve_dotted(name)
                if why:
                    bad.append(f"{_rel(page.path)}:{n}: `{name}`: {why}")
        for n, span in inline_spans(page):
            path = span.split()[0] if span.split() else ""
            if _PATH.match(path) and not (REPO_ROOT / path).exists():
                bad.append(f"{_rel(page.path)}:{n}: no file or folder {path}")
    assert not bad, "\n".join(bad)


def test_the_checks_catch_a_renamed_flag_a_bad_subcommand_and_a_broken_link(tmp_path,
                                                                        script_help):
    """The checker itself: a planted bad flag, subcommand, script flag and link are found."""
    page_path = tmp_path / "page.md"
    text = (
        "```bash\n"
        ".venv/bin/strl-pose predict a.png b.png --K 1,1,0,0 --no-such-flag\n"
        ".venv/bin/strl-pose frobnicate --json\n"
        "python3 -m venv .venv && .venv/bin/python examples/train.py --steps 3 \\\n"
        "    --stepz 4 --out runs/x   # a comment --not-a-flag\n"
        "```\n"
        "Inline: `strl-pose evaluate --num-pairs 3 --num-pairz 4` and [a link](nowhere.md),\n"
        "[a heading](#nope).\n\n# A heading\n"
    )
    page_path.write_text(text)
    page = parse_markdown(page_path)
    errors = "\n".join(e for c in page_commands(page)
                       for e in command_errors(c, script_help))
    assert "strl-pose predict has no flag --no-such-flag" in errors
    assert "unknown subcommand 'strl-pose frobnicate'" in errors
    assert "examples/train.py has no flag --stepz" in errors
    assert "strl-pose evaluate has no flag --num-pairz" in errors
    for fine in ("--K ", "--steps ", "--out ", "--num-pairs ", "--not-a-flag"):
        assert f"no flag {fine}" not in errors + " "
    links = "\n".join(link_errors(page))
    assert "missing file: nowhere.md" in links and "missing heading #nope" in links
    assert "#a-heading" not in links
    assert resolve_dotted("strl_pyg.fusion")
    assert resolve_dotted("strl_pyg.inference.estimator.NoSuchName")
    assert resolve_dotted("strl_pyg.inference.estimator.PoseEstimator") is None
