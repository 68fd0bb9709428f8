"""The `drograsp` command line: one subcommand per module in `planner.commands`.

Each command module exposes `register(subparsers)` which adds its parser and sets
`func` (called with the parsed namespace, returning an exit code). Adding a command
means adding a module and naming it in COMMANDS, nothing else.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from models.errors import DrograspError

# Order is the order shown in `drograsp --help`.
COMMANDS: tuple[str, ...] = (
    "demo",
    "plan",
    "view",
    "validate",
    "export",
    "hands",
    "objects",
    "jobs",
    "batch",
    "dataset",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="drograsp",
        description=(
            "Language-guided, cross-embodiment functional dexterous grasp planning: "
            "give an object, an instruction and a hand; get a grasp that holds."
        ),
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"planner.commands.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except DrograspError as err:
        print(f"drograsp {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into e.g. `head`, which stopped reading
        # Python would report the pipe again when it flushes stdout at exit (see the signal
        # module's docs on SIGPIPE): point stdout at /dev/null first.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1


if __name__ == "__main__":
    sys.exit(main())
