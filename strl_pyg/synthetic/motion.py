"""Camera motions from view 0 to view 1.

Poses here are camera-to-world ``(R_wc, c)`` (world ``y`` down, camera ``x`` right, ``y`` down,
``z`` forward). ``d`` is the scene depth of view 0: the distance along its optical axis to the
first surface, clamped to the kind's range (or the distance to the object for the object kind).
Translations are in multiples of ``d`` and are then multiplied by ``SceneConfig.baseline_scale``.

========== ============================================== =====================================
motion     translation (view-0 camera frame)              rotation
========== ============================================== =====================================
forward    ``z`` U(0.04, 0.12) d; ``x, y`` within 0.01 d   yaw 3, pitch 1.5, roll 1 deg at most
lateral    ``x`` +-U(0.04, 0.12) d; ``y`` 0.01 d, ``z``    yaw 3, pitch 1.5, roll 1 deg at most
           0.02 d at most
orbit      around the centre point (the object centre,     U(5, 25) deg about a near-vertical
           or on the optical axis at depth ``d``, nearer   axis, +-5 deg of elevation, 1 deg
           if the free space needs): keeps looking at it   jitter
handheld   random direction, U(0.01, 0.05) d               random axis, U(0.5, 5) deg
rotation   random direction, at most 0.005 d (tiny)        random axis, U(5, 15) deg
wide       as orbit                                        U(20, 40) deg about a near-vertical
                                                           axis
========== ============================================== =====================================

Except for the object kind, the translation is then capped at the kind's free space (so the
camera stays on the road or in the room; the default orbit centre is chosen near enough for
the orbit to fit, so the cap only trims the few percent that the elevation change adds).
"""

from __future__ import annotations

import numpy as np

__all__ = ["axis_angle", "look_at", "move_camera", "scene_depth"]

_DEG = np.pi / 180.0


def axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation ``[3, 3]`` of ``angle`` radians about ``axis`` (Rodrigues)."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    Kx = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * Kx + (1 - np.cos(angle)) * Kx @ Kx


def look_at(c: np.ndarray, target: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """Camera-to-world rotation of a camera at ``c`` looking at ``target``, world ``y`` down
    (image ``y`` points down the world), rolled by ``roll`` radians about its axis."""
    z = np.asarray(target, dtype=np.float64) - np.asarray(c, dtype=np.float64)
    z = z / np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    if np.linalg.norm(x) < 1e-6:  # looking straight up or down
        x = np.array([1.0, 0.0, 0.0])
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    return np.column_stack([x, y, z]) @ axis_angle([0.0, 0.0, 1.0], roll)


def scene_depth(quads, c: np.ndarray, R_wc: np.ndarray) -> float:
    """Distance along the optical axis of the camera ``(R_wc, c)`` to the nearest quad
    (``inf`` when the axis hits none)."""
    if not quads:
        return float("inf")
    d = R_wc[:, 2]
    O = np.stack([q.origin for q in quads])
    U = np.stack([q.u for q in quads])
    V = np.stack([q.v for q in quads])
    # Solve O + s U + t V = c + lam d for (s, t, lam) per quad.
    A = np.stack([U, V, -np.broadcast_to(d, U.shape)], axis=2)  # [Q, 3, 3]
    ok = np.abs(np.linalg.det(A)) > 1e-12
    if not ok.any():
        return float("inf")
    sol = np.linalg.solve(A[ok], (c - O[ok])[..., None])[..., 0]
    s, t, lam = sol[:, 0], sol[:, 1], sol[:, 2]
    hit = (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1) & (lam > 1e-6)
    return float(lam[hit].min()) if hit.any() else float("inf")


def _rot(yaw: float, pitch: float = 0.0, roll: float = 0.0) -> np.ndarray:
    """Camera-to-world rotation for a camera yawed about ``y``, pitched about ``x``, rolled
    about ``z`` (radians)."""
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    Rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    return Ry @ Rx @ Rz


def _small_rotation(rng: np.random.Generator, yaw: float, pitch: float, roll: float):
    return _rot(*(rng.uniform(-1, 1, 3) * np.array([yaw, pitch, roll]) * _DEG))


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _orbit(rng, R_wc0, c0, centre, depth: float, room: float, lo_deg: float, hi_deg: float):
    angle = rng.choice([-1.0, 1.0]) * rng.uniform(lo_deg, hi_deg) * _DEG
    if centre is None:  # on the optical axis, near enough for the orbit to fit the free space
        radius = min(depth, 0.95 * room / (2 * np.sin(abs(angle) / 2)))
        centre = c0 + R_wc0[:, 2] * radius
    axis = np.array([0.0, 1.0, 0.0]) + rng.normal(0.0, 0.15, 3)
    Q = axis_angle(axis, angle) @ axis_angle(R_wc0[:, 0], rng.uniform(-5, 5) * _DEG)
    c1 = centre + Q @ (c0 - centre)
    R_wc1 = Q @ R_wc0 @ _small_rotation(rng, 1.0, 1.0, 1.0)
    return R_wc1, c1


def move_camera(
    motion: str,
    rng: np.random.Generator,
    R_wc0: np.ndarray,
    c0: np.ndarray,
    depth: float,
    centre: np.ndarray | None = None,
    room: float = np.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Draws view 1 ``(R_wc1, c1)`` from view 0 for one of the motions of the module table.

    Args:
        motion: one of :data:`strl_pyg.synthetic.MOTIONS`.
        depth: ``d``, the scene depth of view 0 (metres, > 0).
        centre: orbit centre (world); default: the point on the optical axis at depth ``d``,
            or nearer where the orbit would otherwise move the camera further than ``room``.
        room: free space around camera 0 (metres), for the default orbit centre.
    """
    d = float(depth)
    if motion == "forward":
        t = np.array([rng.uniform(-0.01, 0.01), rng.uniform(-0.01, 0.01),
                      rng.uniform(0.04, 0.12)]) * d
        return R_wc0 @ _small_rotation(rng, 3.0, 1.5, 1.0), c0 + R_wc0 @ t
    if motion == "lateral":
        t = np.array([rng.choice([-1.0, 1.0]) * rng.uniform(0.04, 0.12),
                      rng.uniform(-0.01, 0.01), rng.uniform(-0.02, 0.02)]) * d
        return R_wc0 @ _small_rotation(rng, 3.0, 1.5, 1.0), c0 + R_wc0 @ t
    if motion == "handheld":
        t = _unit(rng) * rng.uniform(0.01, 0.05) * d
        return R_wc0 @ axis_angle(_unit(rng), rng.uniform(0.5, 5.0) * _DEG), c0 + R_wc0 @ t
    if motion == "rotation":
        t = _unit(rng) * rng.uniform(0.0, 0.005) * d
        return R_wc0 @ axis_angle(_unit(rng), rng.uniform(5.0, 15.0) * _DEG), c0 + R_wc0 @ t
    if motion in ("orbit", "wide"):
        lo, hi = (5.0, 25.0) if motion == "orbit" else (20.0, 40.0)
        centre = None if centre is None else np.asarray(centre, dtype=np.float64)
        return _orbit(rng, R_wc0, c0, centre, d, room, lo, hi)
    raise ValueError(
        f"Expected motion in ('forward', 'lateral', 'orbit', 'handheld', 'rotation', 'wide') "
        f"(got {motion!r})"
    )
