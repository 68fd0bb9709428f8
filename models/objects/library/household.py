"""Household items standing upright (z up): spray bottle, lotion pump, frying pan."""

from __future__ import annotations

import numpy as np

from .shapes import Solid, circle, cylinder_z, hull, revolve, rotation

Parts = dict[str, list[Solid]]


def _box(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> np.ndarray:
    return np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )


def spray_bottle(rng: np.random.Generator) -> Parts:
    """Trigger spray bottle 22-27 cm: oval body, sprayer head with nozzle, hanging trigger."""
    a, Hb = rng.uniform(0.035, 0.045), rng.uniform(0.13, 0.17)
    b, rn = a * rng.uniform(0.65, 0.85), 0.014
    body = hull(
        np.vstack(
            [
                circle((a - 0.003, b - 0.003), 64),
                circle((a, b), 64) + [0, 0, 0.003],
                circle((a, b), 64) + [0, 0, Hb],
                circle(rn, 48) + [0, 0, Hb + 0.03],
            ]
        )
    )
    neck = cylinder_z(rn, rn, Hb + 0.028, Hb + 0.046)
    z0 = Hb + 0.045
    collar = cylinder_z(0.018, 0.018, z0 - 0.01, z0 + 0.015)
    nose = rng.uniform(0.055, 0.065)
    housing = hull(
        np.vstack(
            [
                _box((-0.022, -0.014, z0 + 0.01), (0.02, 0.014, z0 + 0.05)),
                _box((nose - 0.004, -0.009, z0 + 0.026), (nose, 0.009, z0 + 0.047)),
            ]
        )
    )
    nozzle_x = circle(0.006, 24)
    nozzle = hull(
        np.vstack(
            [
                np.c_[np.full(24, x), nozzle_x[:, 0], nozzle_x[:, 1] + z0 + 0.037]
                for x in (nose - 0.002, nose + 0.012)
            ]
        )
    )
    drop = rng.uniform(0.022, 0.03)
    trigger = hull(
        np.vstack(
            [
                _box((0.03, -0.007, z0 + 0.024), (0.046, 0.007, z0 + 0.03)),
                _box((0.036, -0.007, z0 - drop), (0.048, 0.007, z0 - drop + 0.006)),
            ]
        )
    )
    return {"body": [body, neck], "head": [collar, housing, nozzle], "trigger": [trigger]}


def lotion_pump(rng: np.random.Generator) -> Parts:
    """Pump dispenser 17-22 cm: cylindrical body with collar, stem and actuator with nozzle."""
    R, Hb = rng.uniform(0.03, 0.038), rng.uniform(0.11, 0.15)
    body = hull(
        np.vstack(
            [
                circle(R - 0.003, 64),
                circle(R, 64) + [0, 0, 0.003],
                circle(R, 64) + [0, 0, Hb],
                circle(0.016, 48) + [0, 0, Hb + 0.015],
            ]
        )
    )
    collar = cylinder_z(0.016, 0.016, Hb + 0.01, Hb + 0.03)
    stem = cylinder_z(0.005, 0.005, Hb + 0.025, Hb + 0.055)
    rt, zt = rng.uniform(0.012, 0.016), Hb + rng.uniform(0.045, 0.055)
    top = cylinder_z(rt, rt, zt, zt + 0.015)
    reach = rng.uniform(0.035, 0.05)
    nozzle = hull(
        np.vstack(
            [
                _box((0.0, -0.006, zt + 0.004), (0.01, 0.006, zt + 0.014)),
                _box((reach - 0.004, -0.0035, zt + 0.006), (reach, 0.0035, zt + 0.012)),
            ]
        )
    )
    return {"body": [body, collar], "pump": [stem, top, nozzle]}


def pan(rng: np.random.Generator) -> Parts:
    """Frying pan 18-23 cm across with a long handle tilted slightly up."""
    R, H, t = rng.uniform(0.09, 0.115), rng.uniform(0.035, 0.05), 0.004
    rb = rng.uniform(0.8, 0.88) * R
    rbt = rb + (R - rb) * t / H
    outline = np.array([[0, 0], [rb, 0], [R, H], [R - t, H], [rbt - t, t], [0, t]])
    base = np.array([[0, 0], [rb, 0], [rbt, t], [0, t]])
    wall = np.array([[rb - t, 0], [rb, 0], [R, H], [R - t, H]])
    body = revolve(outline, [base, wall], segments=96, sectors=24)
    L, tilt = rng.uniform(0.15, 0.19), rng.uniform(5, 15)
    zh = 0.7 * H
    x0 = rb + (R - rb) * zh / H - 0.45 * t
    grip = hull(
        np.vstack(
            [
                _box((0.0, -0.011, -0.0035), (0.001, 0.011, 0.0035)),
                _box((0.6 * L, -0.013, -0.005), (0.6 * L + 0.001, 0.013, 0.005)),
                _box((L - 0.001, -0.016, -0.0045), (L, 0.016, 0.0045)),
            ]
        )
    )
    handle = grip.transformed(rotation("y", -tilt)).translated((x0, 0, zh))
    return {"body": [body], "handle": [handle]}
