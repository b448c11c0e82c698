"""The commands of the README and docs/troubleshooting.md work as written (issue 32).

Fenced ``bash`` and ``python`` blocks are checked. A block whose info string
says ``long`` after the language (```` ```bash long ````) needs what a test
cannot have or afford (the network, a robot, recorded demonstrations, minutes):
its ``drake-skill`` lines are still parsed by the real argument parser and its
Python imports are executed. In every block:

- ``make TARGET``: the Makefile defines TARGET;
- ``drake-skill ARGS`` (or ``.venv/bin/drake-skill``): ``build_parser()``
  accepts ARGS; the quick ones (``--help``, ``--print-config``, ``skills``) run
  as a process and must exit with status 0;
- a ``python`` block that is not ``long`` runs as a script in a temporary folder.
"""

import ast
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from drake_skill.cli.main import UsageError, build_parser

ROOT = Path(__file__).resolve().parent.parent
DOCUMENTS = ("README.md", "docs/troubleshooting.md")
FENCE = re.compile(r"^```(\w+)([^\n]*)\n(.*?)^```", re.S | re.M)


def blocks(language: str) -> list[tuple[str, int, bool, str]]:
    """(document, block number, long, code) of every fenced block of ``language``."""
    found = []
    for name in DOCUMENTS:
        for i, m in enumerate(FENCE.finditer((ROOT / name).read_text())):
            if m.group(1) == language:
                found.append((name, i, "long" in m.group(2).split(), m.group(3)))
    return found


def shell_lines(code: str) -> list[list[str]]:
    """The commands of a bash block, comments dropped and continuation lines joined."""
    text = re.sub(r"\\\n", " ", code)
    return [shlex.split(line, comments=True) for line in text.splitlines() if shlex.split(line, comments=True)]


def drake_skill_argv(words: list[str]) -> list[str] | None:
    """ARGS of a ``drake-skill ARGS`` command line, or None for another program."""
    if words and Path(words[0]).name == "drake-skill":
        return words[1:]
    return None


def quick(argv: list[str]) -> bool:
    return "--help" in argv or "--print-config" in argv or argv[:1] == ["skills"]


#: The make and drake-skill lines (others, such as creating a venv, are the reader's own shell).
COMMANDS = [(f"{doc}:{i}:{' '.join(words)}", words) for doc, i, _, code in blocks("bash")
            for words in shell_lines(code) if words[0] == "make" or drake_skill_argv(words) is not None]


def test_the_documents_have_commands_and_code():
    assert len([c for c in COMMANDS if drake_skill_argv(c[1]) is not None]) >= 15
    assert any(not long for _, _, long, _ in blocks("python"))


@pytest.fixture(scope="module")
def parser():
    return build_parser()


@pytest.mark.parametrize("words", [w for _, w in COMMANDS], ids=[name for name, _ in COMMANDS])
def test_command_parses(words, parser):
    argv = drake_skill_argv(words)
    if words[0] == "make":
        targets = re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(), re.M)
        assert words[1] in targets, f"the Makefile has no target {words[1]!r}"
        return
    try:
        parser.parse_args(argv)
    except SystemExit as e:           # --help
        assert e.code in (0, None)
    except UsageError as e:
        pytest.fail(f"drake-skill {' '.join(argv)}: {e}")


QUICK = [(name, drake_skill_argv(w)) for name, w in COMMANDS
         if drake_skill_argv(w) is not None and quick(drake_skill_argv(w))]


@pytest.mark.parametrize("argv", [a for _, a in QUICK], ids=[name for name, _ in QUICK])
def test_quick_command_runs(argv):
    done = subprocess.run([sys.executable, "-m", "drake_skill.cli.main", *argv], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip()


PYTHON = blocks("python")


@pytest.mark.parametrize("doc, index, long, code", PYTHON, ids=[f"{d}:{i}" for d, i, _, _ in PYTHON])
def test_python_block(doc, index, long, code, tmp_path):
    if long:      # its imports only: the names it uses exist where it says
        tree = ast.parse(code)
        code = "\n".join(ast.unparse(n) for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom)))
    script = tmp_path / "block.py"
    script.write_text(code)
    done = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"{doc} block {index}:\n{done.stderr[-3000:]}"
