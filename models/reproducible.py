"""Rounding that keeps a plan the same whichever BLAS kernels the machine picks.

A plan's outcome is chaotic in the last bits of its inputs: SNOPT's 150 iterations turn a 1e-16
difference into answers millimetres apart, and MuJoCo's closing into another verdict. OpenBLAS
picks its kernels per processor (numpy's copy and the one inside Drake), so the same proposal
computed on two machines can differ in its last bits. The values handed from one stage to the
next (principal axes and proposals, the program's start and targets, solved configurations,
pregrasps, the qualities that order candidates, hull vertices) are therefore rounded to
`DECIMALS` places, a nanometre: far below any physical scale, far above floating-point noise.
With OpenBLAS forced to other kernels (OPENBLAS_CORETYPE=Nehalem or Prescott), LEAP's proposals
and solves on mug 3 are then bit-identical; before, the solves' anchor errors moved by up to
14 mm. Not every source is covered: with numpy's AVX2 and FMA3 loops disabled
(NPY_DISABLE_CPU_FEATURES), Drake's forward kinematics from the same positions still changes in
the last bit, by a path not found, and so do the plans. Figures therefore reproduce exactly on
the same kind of machine with the pinned packages (constraints.txt), elsewhere within a few
points (docs/planner_log.md, "Reproducing the figures").
"""

from __future__ import annotations

import numpy as np

DECIMALS = 9


def rounded(values):
    """`values` (array or float) rounded to DECIMALS places, as float64."""
    if np.isscalar(values):
        return float(np.round(float(values), DECIMALS))
    return np.round(np.asarray(values, dtype=float), DECIMALS)


def rounded_within(values, lower, upper) -> np.ndarray:
    """Joint values rounded, then clipped: a limit with more decimals than DECIMALS stays the
    limit instead of rounding past it."""
    return np.clip(rounded(values), lower, upper)
