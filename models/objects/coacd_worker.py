"""CoACD in its own process: `python -m models.objects.coacd_worker IN.npz OUT.npz OPTIONS_JSON`.

CoACD aborts the process on some geometry (a C++ assertion) and never returns on others (open
meshes), so `collision.coacd_pieces` runs it here, where an abort is an exit status and a hang
a time limit, and the caller turns either into a clear error.
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np


def main(argv: list[str]) -> int:
    src, dst, options = argv
    import coacd

    with np.load(src) as data:
        verts, faces = data["vertices"], data["faces"]
    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(verts, faces), **json.loads(options))
    arrays = {f"v{i}": np.asarray(v, dtype=np.float64) for i, (v, _) in enumerate(parts)}
    tmp = f"{dst}.{os.getpid()}.tmp.npz"
    np.savez(tmp, count=len(parts), **arrays)
    os.replace(tmp, dst)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
