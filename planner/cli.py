"""The `drograsp` command line: one subcommand per module in `planner.commands`.

Each command module exposes `register(subparsers)` which adds its parser and sets
`func` (called with the parsed namespace, returning an exit code). Adding a command
means adding a module and naming it in COMMANDS, nothing else.

Start-up stays under a second for `--help` and argument errors: only the module of the command
asked for is imported (the others appear in `--help` by their one-line help, below), and command
modules import torch, Drake, MuJoCo and trimesh only when they run.

Exit codes: 0 success; 1 the command ran but found no grasp that holds; 2 bad input or usage
(the message says what to fix); 130 interrupted (Ctrl+C); 141 output pipe closed early.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from models.errors import DrograspError

EXIT_OK, EXIT_NO_GRASP, EXIT_BAD_INPUT = 0, 1, 2

# Order is the order shown in `drograsp --help`; the text is each command's one-line help
# (tests/test_cli.py checks it against the modules').
COMMANDS: dict[str, str] = {
    "demo": "plan three instructions on built-in objects with every hand; write viewer pages",
    "plan": "plan a functional grasp for an object, an instruction and a hand",
    "view": "show a grasp in Meshcat (live on localhost, or as a self-contained HTML page)",
    "validate": "simulate grasps (DexGraspBench layout) and report which hold",
    "export": "write grasps in another benchmark's layout (DexGraspBench)",
    "hands": "list the built-in hands (DoF, joints, actuators and couplings, fingertips, "
    "anchor fingers)",
    "objects": "list the procedural object library, export an object, label a mesh, draw the "
    "contact sheet",
    "jobs": "make a batch jobs file (JSONL) for `drograsp batch`",
    "batch": "solve a jobs file offline (local process pool or Ray), resumably",
    "dataset": "generate, compact and inspect the functional grasp dataset",
    "train": "train a learned model (the interaction diffusion model) on a grasp dataset",
}

EPILOG = (
    "exit codes: 0 success; 1 ran but found no grasp that holds; 2 bad input or usage; "
    "130 interrupted"
)


def _chosen(argv: list[str]) -> str | None:
    """The command named on the command line (the first word that is not an option)."""
    return next((a for a in argv if not a.startswith("-")), None)


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser with the chosen command's full parser (every command's when `argv` is
    None) and the others' one-line help."""
    parser = argparse.ArgumentParser(
        prog="drograsp",
        description=(
            "Language-guided, cross-embodiment functional dexterous grasp planning: "
            "give an object, an instruction and a hand; get a grasp that holds."
        ),
        epilog=EPILOG,
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    chosen = None if argv is None else _chosen(argv)
    for name, text in COMMANDS.items():
        if argv is None or name == chosen:
            importlib.import_module(f"planner.commands.{name}").register(sub)
        else:
            sub.add_parser(name, help=text, add_help=False)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_BAD_INPUT
    try:
        return int(args.func(args) or 0)
    except DrograspError as err:
        print(f"drograsp {args.command}: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into e.g. `head`, which stopped reading
        # Python would report the pipe again when it flushes stdout at exit (see the signal
        # module's docs on SIGPIPE): point stdout at /dev/null first.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
