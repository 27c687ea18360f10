"""What every command's --help ends with: its examples, notes and exit codes
(``set_epilog``), laid out as written (RawDescriptionHelpFormatter)."""
from __future__ import annotations

import argparse

#: The exit codes of a command that reads inputs and writes outputs.
EXIT_CODES = """exit codes:
  0              success
  2              bad usage or input: one line names the option, or the file, line and field
                 (checked before the work starts; no output is left half-written)
  130, 143, 129  stopped by Ctrl-C, SIGTERM, SIGHUP (the outputs are completed)"""


def set_epilog(parser: argparse.ArgumentParser, examples: str, notes: str = "", exit_codes: str = EXIT_CODES) -> None:
    """End ``parser``'s help with "examples:" (``examples``: one command per line, a
    comment after '#'), ``notes`` (a paragraph, may be empty) and ``exit_codes``."""
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    lines = "\n".join(f"  {line}" for line in examples.strip("\n").splitlines())
    parts = [f"examples:\n{lines}", notes.strip("\n"), exit_codes]
    parser.epilog = "\n\n".join(p for p in parts if p)


def example_commands(parser: argparse.ArgumentParser) -> list[str]:
    """The command lines of ``parser``'s examples (without their comments): for tests
    that check every example parses."""
    text = (parser.epilog or "").split("\n\n")[0]
    if not text.startswith("examples:"):
        return []
    return [line.split(" #")[0].strip() for line in text.splitlines()[1:] if line.strip().startswith("fogmon ")]
