"""A PNG contact sheet of the library: one tile per category, faces coloured by part.

Rendered with matplotlib's Agg backend (no display, no OpenGL), so it works on a headless server.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .generate import make_object
from .library import categories
from .splits import HELDOUT

PALETTE = ("#d9843b", "#3b7dd9", "#49a85c", "#c44e8a", "#8a6cc4", "#c4b23b")
LIGHT = np.array([0.4, -0.5, 0.75]) / np.linalg.norm([0.4, -0.5, 0.75])


def write_sheet(out: str | Path, seed: int = 0, columns: int = 4, dpi: int = 110) -> Path:
    """Render instance `seed` of every category into one PNG at `out`; returns the path."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    names = categories()
    rows = -(-len(names) // columns)
    fig = plt.figure(figsize=(3.2 * columns, 3.4 * rows))
    for i, name in enumerate(names):
        obj = make_object(name, seed)
        mesh = obj.mesh
        ax = fig.add_subplot(rows, columns, i + 1, projection="3d")
        base = np.array(
            [matplotlib.colors.to_rgb(PALETTE[k % len(PALETTE)]) for k in obj.face_labels]
        )
        shade = 0.45 + 0.55 * np.clip(mesh.face_normals @ LIGHT, 0, 1)
        colours = np.clip(base * shade[:, None], 0, 1)
        ax.add_collection3d(
            Poly3DCollection(mesh.triangles, facecolors=colours, edgecolors=colours, linewidths=0.2)
        )
        half = 0.5 * float(mesh.extents.max())
        for setter in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
            setter(-half, half)
        ax.set_box_aspect((1, 1, 1), zoom=1.3)
        ax.view_init(elev=22, azim=-60)
        ax.set_axis_off()
        size = " x ".join(f"{100 * e:.0f}" for e in mesh.extents)
        held = " (held out)" if name in HELDOUT else ""
        ax.set_title(f"{name}{held}\n{size} cm", fontsize=9)
        handles = [
            Patch(color=PALETTE[k % len(PALETTE)], label=p) for k, p in enumerate(obj.part_names)
        ]
        ax.legend(
            handles=handles,
            loc="lower center",
            fontsize=7,
            ncol=len(handles),
            frameon=False,
            bbox_to_anchor=(0.5, -0.08),
            handlelength=1.0,
            columnspacing=0.8,
        )
    fig.suptitle(f"drograsp procedural objects (seed {seed}), parts coloured", fontsize=12)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    plt.close(fig)
    return out
