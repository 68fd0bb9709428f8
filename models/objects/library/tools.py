"""Hand tools lying flat on a table, long axis along x: knife, hammer, screwdriver, pen, scissors."""

from __future__ import annotations

import numpy as np

from .shapes import Solid, circle, hull, rotation, tube

Parts = dict[str, list[Solid]]


def _section_x(x: float, radius: float | tuple[float, float], sides: int = 32) -> np.ndarray:
    """A circle or ellipse (radii along y, z) in the plane x = const."""
    c = circle(radius, sides)
    return np.stack([np.full(sides, x), c[:, 0], c[:, 1]], 1)


def knife(rng: np.random.Generator) -> Parts:
    """Kitchen knife 20-28 cm: wedge blade with a curved edge, oval handle."""
    Lh, Lb = rng.uniform(0.10, 0.13), rng.uniform(0.10, 0.15)
    ay, bz = rng.uniform(0.010, 0.012), rng.uniform(0.008, 0.0095)
    handle = hull(
        np.vstack(
            [
                _section_x(0.0, (ay, bz)),
                _section_x(-0.6 * Lh, (ay * 1.05, bz * 1.05)),
                _section_x(-Lh, (ay * 0.95, bz * 0.9)),
                _section_x(-Lh - 0.006, (ay * 0.6, bz * 0.6)),
            ]
        )
    )
    w, ts = rng.uniform(0.022, 0.035), rng.uniform(0.0018, 0.0025)
    spine = 0.7 * ay
    x = np.linspace(-0.015, Lb, 24)
    x0 = 0.55 * Lb
    edge = spine - w + w * (np.clip(x - x0, 0, None) / (Lb - x0)) ** 2
    thick = ts * (1 - 0.8 * np.clip(x, 0, None) / Lb)
    pts = []
    for sign in (-1, 1):
        pts.append(np.stack([x, np.full_like(x, spine), sign * thick / 2], 1))
        pts.append(np.stack([x, edge, np.full_like(x, sign * 0.0002)], 1))
    blade = hull(np.vstack(pts))
    return {"blade": [blade], "handle": [handle]}


def hammer(rng: np.random.Generator) -> Parts:
    """Claw hammer 23-29 cm: tapered oval handle, head with round face and wedge claw."""
    L = rng.uniform(0.22, 0.28)
    ay, bz = rng.uniform(0.013, 0.016), rng.uniform(0.010, 0.012)
    handle = hull(
        np.vstack(
            [
                _section_x(0.0, (ay, bz)),
                _section_x(0.35 * L, (ay * 0.8, bz * 0.8)),
                _section_x(L, (ay * 0.7, bz * 0.75)),
            ]
        )
    )
    rf, lf = rng.uniform(0.012, 0.015), rng.uniform(0.04, 0.05)
    face = circle(rf, 32)
    face_pts = [np.stack([face[:, 0] + L, np.full(32, y), face[:, 1]], 1) for y in (0.0, -lf)]
    striker = hull(np.vstack(face_pts))
    lc = rng.uniform(0.05, 0.06)
    claw = hull(
        np.array(
            [[L + sx * 0.013, 0.0, sz * 0.011] for sx in (-1, 1) for sz in (-1, 1)]
            + [[L + sx * 0.010 + 0.006, lc, sz * 0.003] for sx in (-1, 1) for sz in (-1, 1)]
        )
    )
    collar = hull(
        np.array(
            [
                [L + sx * 0.014, sy * 0.016, sz * 0.012]
                for sx in (-1, 1)
                for sy in (-1, 1)
                for sz in (-1, 1)
            ]
        )
    )
    return {"handle": [handle], "head": [striker, claw, collar]}


def screwdriver(rng: np.random.Generator) -> Parts:
    """Screwdriver 17-24 cm: bulbous handle, steel shaft with a flat tip."""
    Lh, Ls = rng.uniform(0.09, 0.11), rng.uniform(0.07, 0.12)
    rh, rs = rng.uniform(0.013, 0.016), rng.uniform(0.0025, 0.0035)
    handle = hull(
        np.vstack(
            [
                _section_x(-0.006, 0.65 * rh),
                _section_x(0.0, 0.85 * rh),
                _section_x(0.75 * Lh, rh),
                _section_x(Lh, 0.55 * rh),
            ]
        )
    )
    shaft = hull(np.vstack([_section_x(Lh - 0.01, rs, 16), _section_x(Lh + Ls, rs, 16)]))
    tip = hull(
        np.vstack(
            [
                _section_x(Lh + Ls - 0.001, rs, 16),
                [[Lh + Ls + 0.012, sy * rs * 1.1, sz * 0.0004] for sy in (-1, 1) for sz in (-1, 1)],
            ]
        )
    )
    return {"handle": [handle], "shaft": [shaft, tip]}


def pen(rng: np.random.Generator) -> Parts:
    """Capped pen 13-17 cm: conical tip, barrel, cap with a clip."""
    r, Lb, Lc = rng.uniform(0.0045, 0.006), rng.uniform(0.09, 0.11), rng.uniform(0.03, 0.045)
    tip = hull(np.vstack([_section_x(0.001, r), _section_x(-0.018, 0.0008, 12)]))
    barrel = hull(np.vstack([_section_x(0.0, r * 0.92), _section_x(Lb, r)]))
    rc = r + 0.0008
    cap = hull(
        np.vstack(
            [
                _section_x(Lb - 0.005, rc),
                _section_x(Lb + Lc - 0.003, rc),
                _section_x(Lb + Lc, 0.7 * rc),
            ]
        )
    )
    clip = hull(
        np.array(
            [
                [x, sy * 0.0015, z]
                for x in (Lb + Lc - 0.035, Lb + Lc - 0.004)
                for sy in (-1, 1)
                for z in (rc - 0.001, rc + 0.0022)
            ]
        )
    )
    return {"tip": [tip], "barrel": [barrel], "cap": [cap, clip]}


def scissors(rng: np.random.Generator) -> Parts:
    """Scissors 15-21 cm lying flat: two crossed blades on a pivot, two finger rings."""
    Lb, tb = rng.uniform(0.075, 0.1), 0.0018
    open_deg = rng.uniform(4, 14)
    ring = (rng.uniform(0.011, 0.014), rng.uniform(0.009, 0.011))
    shank = rng.uniform(0.02, 0.035)
    blades, handles = [], []
    for side in (1, -1):
        z_lo = 0.0 if side > 0 else -tb
        z_lo -= 0.0003 * side  # the two blades overlap by 0.3 mm so the union is one solid
        outline = np.array(
            [[-0.008, -0.007], [-0.008, 0.009], [Lb, 0.0012], [Lb, -0.0004], [0.5 * Lb, -0.004]]
        )
        outline[:, 1] *= side
        pts = np.vstack([np.c_[outline, np.full(5, z)] for z in (z_lo, z_lo + tb)])
        blade = hull(pts).transformed(rotation("z", side * open_deg / 2))
        blades.append(blade)
        zc = z_lo + tb / 2
        centre = np.array([-shank - ring[0], -side * 0.02, zc])
        t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
        loop = np.stack([ring[0] * np.cos(t), ring[1] * np.sin(t), np.zeros_like(t)], 1) + centre
        handles.append(tube(loop, (0.003, 0.0028), sides=12, closed=True, per_piece=4))
        start = np.array([-0.004, -side * 0.004, zc])
        end = centre + [ring[0] * 0.9, side * ring[1] * 0.45, 0]
        handles.append(tube(np.linspace(start, end, 4), (0.0035, 0.0026), sides=12, per_piece=3))
    screw = hull(np.vstack([circle(0.0035, 24) + [0, 0, z] for z in (-tb - 0.0008, tb + 0.0008)]))
    return {"blade": [*blades, screw], "handle": handles}
