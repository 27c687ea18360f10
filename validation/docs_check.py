"""Docs that run (issue 31.3): every shell command and Python block of README.md and
docs/*.md is run, and every number the docs quote from its output is compared with what
it prints, at the precision quoted.

Run:  python validation/docs_check.py [--fast] [--doc docs/methods.md] [--list]
Prints one line per command (ran / skipped and why / failed), every mismatch (the doc's
line beside the printed one), then PASS or FAIL. Exit 0 on PASS.

The conventions the docs follow (README.md, "Docs that run"):

- A fenced ```bash block is a list of commands, one a line (a line ending in '\\'
  continues); a ```python block is one program. Each doc runs in a fresh temporary copy
  of the repository's files (git ls-files), its blocks in order in that one folder, with
  the fogmon of the running Python's environment, so a file one command writes is there
  for the next. An install prefix `python3 -m venv .venv && . .venv/bin/activate &&
  pip install -e ... &&` is taken as done: what follows it runs.
- A command is not run when the comment lines right above it (or its own trailing
  comment) say `(not run by the docs check: REASON)`, visible in the doc: a device, a
  viewer, another machine, hours. The reason is printed. `(slow: REASON)` there runs
  it only without --fast.
- A ```text block right after a command block is what its last command prints: each
  of its lines must be a printed line, in order (lines may be left out; '...' in a line
  stands for any text). Text must be equal; a number must equal the printed one rounded
  to the digits the doc shows (the doc's 30.4 matches a printed 30.37, not 30.46).
- Prose quoting a command's output names what it quotes in an HTML comment after it,
  `<!-- docs-check: k1_pos +31.49; 1.393 deg/h -> 0.4024 -->`: each ';'-separated item must
  occur in one printed line of the latest command above it (same rules as a text block).
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"^(\s*)```(\w*)\s*$")
SKIP = re.compile(r"\(not run by the docs check: ([^)]+)\)")
SLOW = re.compile(r"\(slow: ([^)]+)\)")
CHECK = re.compile(r"(?<!`)<!--\s*docs-check:\s*(.*?)\s*-->", re.S)
INSTALL = re.compile(r"^python3 -m venv \.venv && \. \.venv/bin/activate && pip install -e \S+ && ")
NUMBER = re.compile(r"(?<![A-Za-z_\d.])([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)(?!\d)")
TIMEOUT_S = 900


@dataclass
class Command:
    """One command (bash line or python block) of a doc: where it is, what to run, why
    not (``skip``), what it must print (``expected`` lines of a text block, ``quotes``
    of docs-check comments, each with its doc line number)."""

    doc: str
    line: int
    lang: str
    text: str
    skip: str = ""
    slow: str = ""
    expected: list[tuple[int, str]] = field(default_factory=list)
    quotes: list[tuple[int, str]] = field(default_factory=list)


# ---------------------------------------------------------------- parsing the docs

def _bash_commands(doc: str, first_line: int, lines: list[str]) -> list[Command]:
    """The commands of a bash block; comment lines above a command (since the last
    command) and its trailing comment may hold a skip or slow marker."""
    out: list[Command] = []
    comments: list[str] = []
    i = 0
    while i < len(lines):
        start = i
        text = lines[i].rstrip()
        while text.endswith("\\") and i + 1 < len(lines):
            i += 1
            text = text[:-1] + " " + lines[i].strip()
        i += 1
        stripped = text.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            comments.append(stripped)
            continue
        notes = " ".join(comments) + " " + stripped
        skip, slow = SKIP.search(notes), SLOW.search(notes)
        out.append(Command(doc, first_line + start, "bash", INSTALL.sub("", stripped),
                           skip.group(1) if skip else "", slow.group(1) if slow else ""))
        comments = []
    return out


def parse_doc(path: Path, rel: str) -> list[Command]:
    """Every command of a doc with its expected output and quotes."""
    lines = path.read_text(encoding="utf-8").splitlines()
    cmds: list[Command] = []
    i = 0
    last_block_end = -10
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            for q in CHECK.finditer(lines[i]):
                if not cmds:
                    raise SystemExit(f"{rel}:{i + 1}: docs-check comment before any command")
                cmds[-1].quotes += [(i + 1, item.strip()) for item in q.group(1).split(";") if item.strip()]
            i += 1
            continue
        indent, lang, j = len(m.group(1)), m.group(2), i + 1
        while j < len(lines) and not lines[j].strip().startswith("```"):
            j += 1
        body = [x[indent:] if not indent or x[:indent].isspace() else x.lstrip() for x in lines[i + 1:j]]
        if lang in ("bash", "sh"):
            cmds += _bash_commands(rel, i + 2, body)
        elif lang == "python":
            text = "\n".join(body)
            skip, slow = SKIP.search(body[0] if body else ""), SLOW.search(body[0] if body else "")
            cmds.append(Command(rel, i + 2, "python", text, skip.group(1) if skip else "",
                                slow.group(1) if slow else ""))
        elif lang == "text" and cmds and all(not x.strip() for x in lines[last_block_end + 1:i]):
            cmds[-1].expected = [(i + 2 + k, x) for k, x in enumerate(body) if x.strip()]
        if lang in ("bash", "sh", "python"):
            last_block_end = j
        i = j + 1
    return cmds


# ---------------------------------------------------------------- comparing output

def tokens(line: str) -> list[str]:
    """A line as words and numbers (numbers not glued to a word: k1_pos is one word)."""
    out: list[str] = []
    for chunk in line.split():
        out += [p for p in NUMBER.split(chunk) if p]
    return out


def _is_number(tok: str) -> bool:
    return NUMBER.fullmatch(tok) is not None


def _step(tok: str) -> float:
    """The value of the last digit the doc shows (30.37 -> 0.01, 6.3e+02 -> 10, 1200 -> 1)."""
    mant, _, exp = tok.lower().lstrip("+-").partition("e")
    decimals = len(mant.split(".")[1]) if "." in mant else 0
    return 10.0 ** (int(exp or 0) - decimals)


def same_token(doc: str, printed: str) -> bool:
    """Equal text, or numbers equal at the doc's precision."""
    if _is_number(doc) and _is_number(printed):
        return abs(float(doc) - float(printed)) <= 0.5 * _step(doc) * (1 + 1e-9)
    return doc == printed


def line_matches(doc: str, printed: str, whole: bool) -> bool:
    """Does a doc line match a printed line: the whole line (``whole``; '...' matches any
    run of tokens) or, for a quote, a contiguous part of it."""
    d, p = tokens(doc), tokens(printed)
    if not whole:
        return any(all(same_token(a, b) for a, b in zip(d, p[k:k + len(d)], strict=True))
                   for k in range(len(p) - len(d) + 1))
    parts = " ".join(d).split("...")
    pieces = [tokens(x) for x in parts]
    if len(pieces) == 1:
        return len(d) == len(p) and all(same_token(a, b) for a, b in zip(d, p, strict=True))
    k = 0
    for n, piece in enumerate(pieces):
        if n == 0:
            if not all(same_token(a, b) for a, b in zip(piece, p[:len(piece)], strict=False)) or len(p) < len(piece):
                return False
            k = len(piece)
            continue
        last = n == len(pieces) - 1
        starts = [len(p) - len(piece)] if last else range(k, len(p) - len(piece) + 1)
        for s in starts:
            if s >= k and all(same_token(a, b) for a, b in zip(piece, p[s:s + len(piece)], strict=True)):
                k = s + len(piece)
                break
        else:
            return False
    return True


def _skeleton(line: str) -> list[str]:
    return [t for t in tokens(line) if not _is_number(t)]


def _closest(doc: str, printed: list[str]) -> str:
    """The printed line most like a doc line (same words), for the mismatch message."""
    sk = _skeleton(doc)
    same = [p for p in printed if _skeleton(p) == sk]
    if same:
        return same[0]
    words = set(sk)
    best = max(printed, key=lambda p: len(words & set(_skeleton(p))), default="")
    return best if words & set(_skeleton(best)) else "(no similar line)"


def compare(cmd: Command, output: str) -> list[str]:
    """Mismatches between what ``cmd`` printed and what its doc says it prints."""
    printed = [x for x in output.splitlines() if x.strip()]
    bad = []
    k = 0
    for line_no, exp in cmd.expected:
        if exp.strip() == "...":
            continue
        for j in range(k, len(printed)):
            if line_matches(exp, printed[j], whole=True):
                k = j + 1
                break
        else:
            bad.append(f"{cmd.doc}:{line_no}: the doc says   {exp.strip()}\n"
                       f"{' ' * len(f'{cmd.doc}:{line_no}: ')}fogmon printed {_closest(exp, printed).strip()}")
    for line_no, quote in cmd.quotes:
        if not any(line_matches(quote, p, whole=False) for p in printed):
            bad.append(f"{cmd.doc}:{line_no}: the doc quotes {quote!r}; printed: {_closest(quote, printed).strip()}")
    return bad


# ---------------------------------------------------------------- running

def docs() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _copy_repository(dest: Path) -> None:
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for rel in files.decode().split("\0"):
        if rel and (ROOT / rel).is_file():
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / rel, dest / rel)


def run(cmd: Command, cwd: Path) -> tuple[int, str, float]:
    """(exit code, stdout + stderr, CPU s of the children) of one command in ``cwd``."""
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "COLUMNS": "120", "FOGMON_DOCS_CHECK": "1"}
    if cmd.lang == "python":
        script = cwd / "_docs_check_block.py"
        script.write_text(cmd.text, encoding="utf-8")
        argv = [sys.executable, "-P", str(script)]    # -P: the installed fogmon, not the copy's (no numba cache)
    else:
        argv = ["bash", "-o", "pipefail", "-c", cmd.text]
    before = os.times()
    try:
        p = subprocess.run(argv, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                           stdin=subprocess.DEVNULL, timeout=TIMEOUT_S, text=True)
        code, out = p.returncode, p.stdout
    except subprocess.TimeoutExpired as e:
        code, out = -1, f"(timed out after {TIMEOUT_S} s)\n{e.output or ''}"
    after = os.times()
    return code, out, (after.children_user - before.children_user) + (after.children_system - before.children_system)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fast", action="store_true", help="leave out the commands marked (slow: ...)")
    ap.add_argument("--doc", action="append", help="check only this doc (repeatable), e.g. docs/methods.md")
    ap.add_argument("--list", action="store_true", help="list the commands and what they are checked against")
    a = ap.parse_args(argv)
    paths = [ROOT / d for d in a.doc] if a.doc else docs()
    problems: list[str] = []
    counts = {"ran": 0, "skipped": 0, "failed": 0}
    for path in paths:
        rel = str(path.relative_to(ROOT))
        cmds = parse_doc(path, rel)
        if a.list:
            for c in cmds:
                what = f"skip: {c.skip}" if c.skip else f"{len(c.expected)} output lines, {len(c.quotes)} quotes"
                print(f"{c.doc}:{c.line}: [{c.lang}] {c.text.splitlines()[0][:90]}  ({what})")
            continue
        if not any(not c.skip for c in cmds):
            continue
        with tempfile.TemporaryDirectory(prefix="fogmon-docs-") as tmp:
            work = Path(tmp)
            _copy_repository(work)
            for c in cmds:
                head = f"{c.doc}:{c.line}: {c.text.splitlines()[0][:100]}"
                if c.skip or (a.fast and c.slow):
                    counts["skipped"] += 1
                    print(f"  skipped  {head}  ({c.skip or 'slow: ' + c.slow})")
                    if (c.expected or c.quotes) and c.skip:
                        problems.append(f"{c.doc}:{c.line}: quotes output of a command the check does not run")
                    continue
                t0 = time.monotonic()
                code, out, cpu = run(c, work)
                wall = time.monotonic() - t0
                mismatches = compare(c, out) if code == 0 else []
                if code != 0:
                    tail = "\n".join("      " + x for x in out.strip().splitlines()[-8:])
                    problems.append(f"{c.doc}:{c.line}: exit {code}: {c.text.splitlines()[0][:100]}\n{tail}")
                problems += mismatches
                ok = code == 0 and not mismatches
                counts["ran" if ok else "failed"] += 1
                checked = len(c.expected) + len(c.quotes)
                print(f"  {'ok' if ok else 'FAILED':7s}  {head}  ({wall:.1f} s, {cpu:.1f} CPU s"
                      f"{f', {checked} lines checked' if checked else ''})", flush=True)
    if a.list:
        return 0
    for p in problems:
        print(p)
    print(f"{counts['ran']} passed, {counts['failed']} failed, {counts['skipped']} skipped")
    print("PASS" if not problems else f"FAIL: {len(problems)} mismatches or failures")
    return 0 if not problems else 1


if __name__ == "__main__":
    sys.exit(main())
