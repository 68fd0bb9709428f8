"""Where slow derived data (CoACD pieces) is kept between runs."""

from __future__ import annotations

import os
from pathlib import Path


def cache_dir(kind: str = "") -> Path:
    """The cache folder: $DROGRASP_CACHE, else $XDG_CACHE_HOME/drograsp, else ~/.cache/drograsp."""
    root = os.environ.get("DROGRASP_CACHE")
    if root:
        base = Path(root).expanduser()
    else:
        xdg = os.environ.get("XDG_CACHE_HOME")
        base = (Path(xdg).expanduser() if xdg else Path.home() / ".cache") / "drograsp"
    path = base / kind if kind else base
    path.mkdir(parents=True, exist_ok=True)
    return path
