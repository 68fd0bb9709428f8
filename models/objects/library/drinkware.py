"""Vessels: mug, cup, bottle, bowl, wine glass, teapot (z up, sizes in metres)."""

from __future__ import annotations

import numpy as np

from .shapes import Solid, arc, circle, cylinder_z, dome_z, hull, revolve, shell_profile, tube

Parts = dict[str, list[Solid]]


def _ring_path(radius: float, z: float, n: int = 48) -> np.ndarray:
    return circle(radius, n) + [0.0, 0.0, z]


def mug(rng: np.random.Generator) -> Parts:
    """Cylindrical mug 8.5-10.5 cm tall with a C handle leaving a finger hole of 1.7 cm or more."""
    R, H = rng.uniform(0.036, 0.045), rng.uniform(0.085, 0.105)
    t, b = rng.uniform(0.004, 0.006), rng.uniform(0.006, 0.009)
    outline = np.array([[0, 0], [R, 0], [R, H], [R - t, H], [R - t, b], [0, b]])
    base = np.array([[0, 0], [R, 0], [R, b], [0, b]])
    wall = np.array([[R - t, 0], [R, 0], [R, H], [R - t, H]])
    body = revolve(outline, [base, wall])
    xc, zc = R - t / 2, rng.uniform(0.5, 0.58) * H
    half = rng.uniform(0.28, 0.36) * H
    reach = rng.uniform(0.024, 0.034)
    section = (rng.uniform(0.005, 0.0065), rng.uniform(0.006, 0.008))
    path = arc((xc, 0, zc), (reach + t / 2, half), -90, 90, 25)
    handle = tube(path, section, sides=16, per_piece=3)
    return {"body": [body], "handle": [handle]}


def cup(rng: np.random.Generator) -> Parts:
    """Tapered drinking cup 8-11 cm tall with a rolled rim."""
    r0, H = rng.uniform(0.026, 0.032), rng.uniform(0.08, 0.11)
    r1, t, b = (
        r0 + rng.uniform(0.008, 0.015),
        rng.uniform(0.0025, 0.0035),
        rng.uniform(0.004, 0.006),
    )
    rb = r0 + (r1 - r0) * b / H
    outline = np.array([[0, 0], [r0, 0], [r1, H], [r1 - t, H], [rb - t, b], [0, b]])
    base = np.array([[0, 0], [r0, 0], [rb, b], [0, b]])
    wall = np.array([[r0 - t, 0], [r0, 0], [r1, H], [r1 - t, H]])
    body = revolve(outline, [base, wall])
    rim = tube(_ring_path(r1 - t / 2, H), rng.uniform(0.0025, 0.0035), closed=True, per_piece=3)
    return {"body": [body], "rim": [rim]}


def bottle(rng: np.random.Generator) -> Parts:
    """Closed bottle 19-27 cm tall, beer or wine style: body with shoulder, a neck long enough to
    wrap the fingers around (4.5-6.5 cm, as fingertips 2 cm apart need), screw cap."""
    Rb, Hb = rng.uniform(0.03, 0.04), rng.uniform(0.11, 0.15)
    hs, rn = rng.uniform(0.02, 0.035), rng.uniform(0.011, 0.014)
    hn, hc = rng.uniform(0.045, 0.065), rng.uniform(0.015, 0.022)
    rc = rn + rng.uniform(0.0015, 0.003)
    body = hull(
        np.vstack(
            [
                circle(Rb - 0.003, 64),
                circle(Rb, 64) + [0, 0, 0.003],
                circle(Rb, 64) + [0, 0, Hb],
                circle(rn, 64) + [0, 0, Hb + hs],
            ]
        )
    )
    top = Hb + hs + hn
    neck = cylinder_z(rn, rn, Hb + hs - 0.002, top)
    cap = cylinder_z(rc, rc, top - 0.006, top + hc - 0.006)
    return {"body": [body], "neck": [neck], "cap": [cap]}


def bowl(rng: np.random.Generator) -> Parts:
    """Round bowl 12-15 cm across, 4.5-6 cm deep, with a rolled rim."""
    R, H = rng.uniform(0.06, 0.075), rng.uniform(0.045, 0.06)
    rb, t = rng.uniform(0.4, 0.5) * R, rng.uniform(0.003, 0.0045)
    u = np.linspace(0, np.pi / 2, 25)
    outer = np.stack([rb + (R - rb) * np.sin(u), H * (1 - np.cos(u))], 1)
    tang = np.gradient(outer, axis=0)
    normal = np.stack([tang[:, 1], -tang[:, 0]], 1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    inner = outer - t * normal
    outline, quads = shell_profile(outer, inner, coarse=6)
    outline = np.vstack([[0, 0], outline, [0, t]])
    base = np.array([[0, 0], [rb, 0], [rb, t], [0, t]])
    body = revolve(outline, [base, *quads])
    rim = tube(_ring_path(R - t / 2, H), rng.uniform(0.003, 0.004), closed=True, per_piece=3)
    return {"body": [body], "rim": [rim]}


def wine_glass(rng: np.random.Generator) -> Parts:
    """Stemmed glass 15-19 cm tall: egg-shaped bowl, thin stem, flat foot."""
    rf, tf = rng.uniform(0.03, 0.037), 0.004
    rs, ls = rng.uniform(0.0035, 0.005), rng.uniform(0.06, 0.08)
    Rm, hb, t = rng.uniform(0.035, 0.042), rng.uniform(0.08, 0.1), 0.0035
    z0 = tf + ls
    foot = hull(np.vstack([circle(rf, 64), circle(rf - 0.002, 64) + [0, 0, tf]]))
    cone = cylinder_z(rf * 0.35, rs, tf - 0.001, tf + 0.008)
    stem = cylinder_z(rs, rs, tf, z0 + 0.004)
    cz = 0.62 * hb
    phi_o = np.radians(np.linspace(-90, np.degrees(np.arcsin((hb - cz) / cz)), 17))
    phi_i = np.radians(np.linspace(-90, np.degrees(np.arcsin((hb - cz) / (cz - t))), 17))
    outer = np.stack([Rm * np.cos(phi_o), cz + cz * np.sin(phi_o)], 1)
    inner = np.stack([(Rm - t) * np.cos(phi_i), cz + (cz - t) * np.sin(phi_i)], 1)
    outer[0, 0] = inner[0, 0] = 0.0
    outline, quads = shell_profile(outer, inner, coarse=3)
    cup_ = revolve(outline, quads, sectors=12).translated((0, 0, z0))
    return {"bowl": [cup_], "stem": [stem, cone], "foot": [foot]}


def teapot(rng: np.random.Generator) -> Parts:
    """Teapot 11-17 cm tall: convex belly, domed lid with knob, tapered spout, C handle."""
    Rb, Hb = rng.uniform(0.055, 0.065), rng.uniform(0.09, 0.11)
    zc = 0.45 * Hb
    cz = zc / 0.694

    def radius(z: float | np.ndarray) -> np.ndarray:
        return Rb * np.sqrt(np.clip(1 - ((np.asarray(z) - zc) / cz) ** 2, 0, 1))

    zs = np.linspace(0, Hb, 17)
    body = hull(np.vstack([circle(float(radius(z)), 64) + [0, 0, z] for z in zs]))
    r_top = float(radius(Hb))
    lid_h = rng.uniform(0.2, 0.3) * Rb
    lid = dome_z(r_top * 1.05, lid_h, Hb - 0.002)
    knob_z = Hb + lid_h - 0.006
    knob = hull(
        np.vstack(
            [
                circle(0.005, 24) + [0, 0, knob_z],
                dome_z(0.011, 0.008, knob_z + 0.01, sides=24).pieces[0],
            ]
        )
    )
    s = np.linspace(0, 1, 14)[:, None]
    p0 = np.array([-0.6 * Rb, 0, 0.3 * Hb])
    p1 = np.array([-1.25 * Rb, 0, 0.35 * Hb])
    p2 = np.array([-rng.uniform(1.45, 1.6) * Rb, 0, rng.uniform(0.9, 1.05) * Hb])
    spout_path = (1 - s) ** 2 * p0 + 2 * s * (1 - s) * p1 + s**2 * p2
    spout = tube(spout_path, np.linspace(0.015, 0.0065, 14), sides=16, per_piece=2)
    zh, half = rng.uniform(0.5, 0.56) * Hb, rng.uniform(0.26, 0.32) * Hb
    xc = float(radius(zh + half)) - 0.008
    reach = Rb - xc + rng.uniform(0.026, 0.034)
    handle = tube(arc((xc, 0, zh), (reach, half), -90, 90, 25), (0.0065, 0.008), per_piece=3)
    return {"body": [body], "lid": [lid, knob], "spout": [spout], "handle": [handle]}
