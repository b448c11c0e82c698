"""``drake-skill``: the command line, one argparse tree.

Every subcommand is a module ``drake_skill/cli/<name>.py`` listed in
:data:`COMMANDS` that defines

* ``NAME``: the subcommand as typed (``"station-demo"``),
* ``HELP``: one line for ``drake-skill --help``,
* ``add_arguments(parser)``: its options on the subparser,
* ``run(args) -> int``: the work (heavy imports such as pydrake and torch go
  inside ``run`` so that ``--help`` stays fast).

A name in :data:`COMMANDS` whose module does not exist yet is skipped, so
commands can be added by dropping a module in and listing it here.

User errors (``ValueError``, ``OSError`` and their subclasses such as
``FileNotFoundError``, ``FileExistsError``, ``NotADirectoryError``, and
argument errors) print one line ``drake-skill: error: ...`` and exit with
status 2; ``--verbose`` adds the traceback. Differential IK's
unreachable-pose warnings are counted instead of printed unless ``--verbose``.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import logging
import os
import re
import sys
import traceback

import yaml

from drake_skill.common import IkWarningCounter

#: Command modules in the order ``--help`` lists them (missing ones are skipped).
COMMANDS = ["skills", "station_demo", "demos", "fit", "learn", "evaluate", "replay", "experiment", "bench", "hardware",
            "sim_robot"]

DESCRIPTION = "Robot skill learning from very few demonstrations, as a Drake diagram."
EPILOG = ("Run 'drake-skill COMMAND --help' for a command's options. User errors print one line "
          "and exit with status 2; --verbose adds the traceback.")


class UsageError(Exception):
    """An argument error from argparse, reported as one line (exit status 2)."""


class Parser(argparse.ArgumentParser):
    """ArgumentParser that raises :class:`UsageError` instead of printing usage and exiting."""

    def error(self, message):
        m = re.match(r"argument (?:command|COMMAND): invalid choice: '([^']*)'", message)
        if m:
            message = f"unknown command '{m.group(1)}' (run 'drake-skill --help' for the list)"
        elif self.prog != "drake-skill":
            message = f"{self.prog[len('drake-skill '):] if self.prog.startswith('drake-skill ') else self.prog}: " \
                      f"{message} (see '{self.prog} --help')"
        raise UsageError(message)

    # Help texts come from docstrings written in reStructuredText; the markup is
    # stripped from the formatted text (format_help / format_usage are public
    # ArgumentParser methods; every subparser is a Parser, nested ones too, as
    # add_subparsers defaults parser_class to the parent's class).
    def format_help(self) -> str:
        return plain(super().format_help())

    def format_usage(self) -> str:
        return plain(super().format_usage())


def plain(text: str | None) -> str:
    """Help text without reStructuredText markup (double backticks, :role:`x` references)."""
    if not text:
        return ""
    text = re.sub(r":[a-z]+:`~?([^`<]*?)(?:\s*<[^>]*>)?`", r"\1", text)
    return text.replace("``", "")


def available_commands() -> list:
    """The command modules of :data:`COMMANDS` that exist, imported (they import nothing heavy)."""
    modules = []
    for name in COMMANDS:
        full = f"drake_skill.cli.{name}"
        if importlib.util.find_spec(full) is None:
            continue
        module = importlib.import_module(full)
        if not all(hasattr(module, a) for a in ("NAME", "HELP", "add_arguments", "run")):
            raise RuntimeError(f"{full}: a command module needs NAME, HELP, add_arguments and run")
        modules.append(module)
    return modules


def _add_common(parser: argparse.ArgumentParser, top: bool) -> None:
    # On subparsers the default is SUPPRESS so that 'drake-skill --verbose fit' is not reset.
    parser.add_argument("--verbose", action="store_true", default=False if top else argparse.SUPPRESS,
                        help="print tracebacks of errors and every differential-IK warning")


def build_parser() -> Parser:
    """The whole command line: the global options and one subparser per command module."""
    from drake_skill import __version__

    parser = Parser(prog="drake-skill", description=DESCRIPTION, epilog=EPILOG)
    parser.add_argument("--version", action="version", version=f"drake-skill {__version__}",
                        help="print the version and exit")
    _add_common(parser, top=True)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands", parser_class=Parser)
    sub.required = True
    for module in available_commands():
        doc = getattr(module, "DESCRIPTION", None) or module.__doc__
        p = sub.add_parser(module.NAME, help=module.HELP, description=doc,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        _add_common(p, top=False)
        module.add_arguments(p)
        p.set_defaults(_run=module.run, _parser=p)
    return parser


def one_line(error: BaseException) -> str:
    """The message of a user error on one line."""
    text = str(error) or type(error).__name__
    if isinstance(error, OSError) and error.filename is not None and str(error.filename) not in text:
        text = f"{error.filename}: {text}"
    return " ".join(part.strip() for part in text.splitlines() if part.strip())


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    verbose = "--verbose" in argv  # known before parsing, so parse errors honour it too
    quiet = IkWarningCounter(suppress=True)
    if not verbose:
        logging.getLogger("drake").addFilter(quiet)
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:  # --help, --version
            return int(e.code or 0)
        try:
            return int(args._run(args) or 0)
        except SystemExit as e:  # a benchmark's own argparse (--help, bad option)
            if e.code is None or isinstance(e.code, int):
                return int(e.code or 0)
            print(f"drake-skill: error: {e.code}", file=sys.stderr)
            return 2
    except BrokenPipeError:
        # The reader went away (``drake-skill skills FILE | head -2``): end quietly, as a
        # filter does. Python's advice: point stdout at devnull, so that the flush at exit
        # does not fail again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except UsageError as e:
        if verbose:
            traceback.print_exc()
        print(f"drake-skill: error: {one_line(e)}", file=sys.stderr)
        return 2
    except (ValueError, OSError, yaml.YAMLError) as e:
        if verbose:
            traceback.print_exc()
        print(f"drake-skill: error: {one_line(e)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if verbose:
            traceback.print_exc()
        print("drake-skill: interrupted", file=sys.stderr)
        return 130
    finally:
        logging.getLogger("drake").removeFilter(quiet)
        if quiet.count:
            print(f"({quiet.count} differential-IK warnings about unreachable hand poses hidden; "
                  "--verbose shows them)", file=sys.stderr)


def command_main(name: str, argv=None) -> int:
    """``drake-skill NAME ARGV...``: for each command module's ``main(argv)`` (scripts, tests)."""
    return main([name, *(sys.argv[1:] if argv is None else list(argv))])


if __name__ == "__main__":
    raise SystemExit(main())
