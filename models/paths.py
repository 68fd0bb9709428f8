"""Paths a user gives, checked at the boundary: inputs that must exist and outputs that can be
written, each refused with a `DrograspError` that names the path and the fix.

Light to import (no numpy), so the CLI checks its arguments before it loads anything heavy.
"""

from __future__ import annotations

import errno
import os
from collections.abc import Sequence
from pathlib import Path

from models.errors import DrograspError


class PathError(DrograspError, ValueError):
    """A path that cannot be read or written: missing, too long, a folder, not writable."""


def _short(text: str) -> str:
    return text if len(text) <= 120 else f"{text[:60]}...{text[-40:]} ({len(text)} characters)"


def as_path(value: object, what: str = "file", error: type[DrograspError] = PathError) -> Path:
    """`value` (str, bytes or os.PathLike) as a Path with `~` expanded, or `error`."""
    if isinstance(value, bytes):
        value = os.fsdecode(value)
    if not isinstance(value, str | os.PathLike):
        raise error(f"the {what} must be a path (str or Path), got {type(value).__name__}")
    text = os.fspath(value)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if not text.strip():
        raise error(f"the {what} path is empty; give a file name")
    if "\x00" in text:
        raise error(f"the {what} path {text!r} contains a NUL character; give a plain file name")
    try:
        path = Path(text).expanduser()
    except RuntimeError:  # "~user" of an unknown user
        raise error(
            f"cannot expand {_short(text)}: no user of that name has a home folder; give the "
            "full path"
        ) from None
    for part in path.parts:
        if len(os.fsencode(part)) > 255:
            raise error(
                f"the {what} path {_short(text)} has a name longer than 255 bytes, more than "
                "file systems allow; use a shorter name"
            )
    return path


def input_file(value: object, what: str = "file", error: type[DrograspError] = PathError) -> Path:
    """An existing, readable regular file."""
    path = as_path(value, what, error)
    try:
        if path.is_dir():
            raise error(f"{_short(str(path))} is a folder; give the {what} inside it")
        if not path.is_file():
            raise error(
                f"no such {what}, not found: {_short(str(path))}; check the path and the working "
                "folder"
            )
    except OSError as err:
        raise error(f"cannot use {_short(str(path))} as the {what}: {err.strerror}") from None
    if not os.access(path, os.R_OK):
        raise error(f"{_short(str(path))} is not readable; check its permissions")
    return path


def input_folder(
    value: object, what: str = "folder", error: type[DrograspError] = PathError
) -> Path:
    """An existing folder."""
    path = as_path(value, what, error)
    try:
        if not path.exists():
            raise error(f"{what} not found: {_short(str(path))}; check the path")
        if not path.is_dir():
            raise error(f"{_short(str(path))} is a file, not a {what}")
    except OSError as err:
        raise error(f"cannot use {_short(str(path))} as the {what}: {err.strerror}") from None
    return path


def _make_folder(folder: Path, what: str, error: type[DrograspError]) -> None:
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise error(
            f"cannot write the {what} into {_short(str(folder))}: a file of that name is in the "
            "way; choose another folder"
        ) from None
    except OSError as err:
        reason = (
            "a part of it is a file, not a folder"
            if err.errno == errno.ENOTDIR
            else err.strerror or str(err)
        )
        raise error(
            f"cannot create the folder {_short(str(folder))} for the {what}: {reason}; choose a "
            "folder you can write to"
        ) from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise error(f"cannot write the {what} into {_short(str(folder))}: permission denied")


def output_file(
    value: object,
    suffixes: Sequence[str],
    what: str = "output",
    error: type[DrograspError] = PathError,
) -> Path:
    """A file that can be written: its extension is one of `suffixes` (which name the format),
    its folder exists or is created now, and it is not a folder. Called before the work, so a
    bad `--out` costs nothing."""
    path = as_path(value, what, error)
    suffix = path.suffix.lower()
    if suffixes and suffix not in suffixes:
        raise error(
            f"the {what} {_short(str(path))} must end in {' or '.join(suffixes)} (the extension "
            f"names the format written), not {suffix or 'no extension'!r}"
        )
    if path.is_dir():
        raise error(f"the {what} {_short(str(path))} is a folder; give a file name inside it")
    _make_folder(path.parent, what, error)
    return path


def output_folder(
    value: object, what: str = "output folder", error: type[DrograspError] = PathError
) -> Path:
    """A folder that exists or is created now."""
    path = as_path(value, what, error)
    _make_folder(path, what, error)
    return path


def write_text_atomic(path: Path, text: str, what: str = "output") -> Path:
    """Write through a temporary file beside `path`, then rename: a failure never leaves half
    a file, and an existing file stays whole until the new one is complete."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise PathError(f"could not write the {what} {_short(str(path))}: {err}") from None
    return path
