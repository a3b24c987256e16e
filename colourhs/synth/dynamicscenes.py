"""Dynamic multi-coloured scenes: sequences whose chromaticity moves with the surface.

The scenes of the ``dynamic`` presets (:data:`colourhs.synth.synthesise.PRESETS`),
each a sequence of ``frames`` frames (12 in those presets), phase
s = f / (frames - 1) at frame f:

``moving-toy``
    The multi-coloured toy dog (:func:`colourhs.synth.scenes.toy`) moving
    rigidly at constant velocity: a rotation by ``angle_deg`` about an axis
    through its bounding-box centre and a translation of that centre by
    ``translation_m`` over the sequence (:class:`RigidMotion`). Fixed presets:
    :data:`TOY_MOTION_ANGLE_DEG` (20 deg) about :data:`TOY_MOTION_AXIS` and
    :data:`TOY_MOTION_TRANSLATION_M` (34.2 mm); random presets:
    :data:`RANDOM_TOY_TRANSLATION_M` (2-5 cm in a uniform direction) and
    :data:`RANDOM_TOY_ROTATION_DEG` (10-30 deg about a uniform axis).
``cloth``
    A multi-coloured cloth deforming as the white ``sheet`` does (the same
    height field, :func:`colourhs.synth.scenes.sheet`): :data:`CLOTH_PATCHES`
    (5 x 4) patches of pure and mixed colours (:data:`CLOTH_COLOURS`), in a
    checkerboard of a white-specular dielectric (coloured diffuse under a
    white GGX lobe) and a coloured diffuse (Lambertian) material.
``turning-metal``
    A three-lobed object of two coloured metals (a body and three inlaid
    stripes; GGX with a per-band Fresnel F0, :data:`METALS`) turning about its
    own axis: fixed presets :data:`METAL_TURN_DEG` (90 deg), the axis tilted
    :data:`METAL_TILT_DEG` (15 deg) towards the rig; random presets
    :data:`RANDOM_METAL_TURN_DEG` and :data:`RANDOM_METAL_TILT_DEG`.

The chromatic captures show the toy and the cloth in their first frame and the
metal in frame ``(frames - 1) // 2``. In the random presets
(:func:`random_sequences`) the toy and the metal are placed as the static
objects are (:mod:`colourhs.synth.randomrig`'s table: scale, position) and
redrawn until every frame is in every view; the cloth is the draw's sheet
(size, tilt, dielectric) with its patches' colours shuffled. These draws come
from the seed's own ``dynamic-scenes`` stream.

The surface chromaticity p (the paper's eq. 4: reflectance per light band R, G,
B, the ``albedo`` of a :class:`~colourhs.synth.scenes.SceneGeometry`) of every
scene is a function of the surface point in the object's own rest
coordinates, never of the world point: the rigid objects map a hit point back
through their pose (:func:`colourhs.synth.scenes.transformed`), the cloth
through the barycentric coordinates of its triangle (:func:`rest_albedo`). A
surface point keeps its p in every frame, and every frame's ground-truth mesh
lists the same surface points in the same vertex order.

Beyond the paper: its chromaticity calibration (Section III-D) reads p per
camera pixel from chromatic captures of the object in the pose it is
reconstructed in, and its dynamic scenes are white. Here the chromatic
captures show the object in one frame only (``Sequence.chromatic_frame``,
scene.json's ``chromatic_frame``) while it moves through the others, as a
moving coloured object would be captured.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy.spatial import ConvexHull

from colourhs.common.geometry import axis_angle, outward_triangles, vertex_normals
from colourhs.synth import scenes as sc
from colourhs.synth.brdf import Material
from colourhs.synth.poses import in_view
from colourhs.synth.randomranges import METALS, RandomRanges, _stream
from colourhs.synth.randomscenes import (
    _base_geometry,
    _object_shapes,
    _sheet_material,
    _toy_materials,
    _yaw,
)

#: The scenes of a dynamic preset, besides the held-out board ``plane``.
DYNAMIC_SCENES = ("moving-toy", "cloth", "turning-metal")

TOY_MOTION_AXIS = (0.3, 1.0, 0.0)
"""Axis of the fixed presets' toy rotation (world, any length): mostly vertical."""

TOY_MOTION_ANGLE_DEG = 20.0
"""The fixed presets' toy turns by this much over the sequence, degrees."""

TOY_MOTION_TRANSLATION_M = (-0.025, 0.012, 0.02)
"""The fixed presets' toy centre moves by this much over the sequence, metres
(34.2 mm: left, down and away from the rig)."""

RANDOM_TOY_TRANSLATION_M = (0.02, 0.05)
"""Random presets: length of the toy's translation over the sequence, U(a, b) m."""

RANDOM_TOY_ROTATION_DEG = (10.0, 30.0)
"""Random presets: the toy's rotation over the sequence, U(a, b) deg."""

METAL_TURN_DEG = 90.0
"""The fixed presets' metal turns by this much about its axis over the sequence,
degrees, from -45 to +45 deg (facing the rig at mid-sequence)."""

METAL_TILT_DEG = 15.0
"""The fixed presets' metal axis leans its top this much towards the rig, degrees."""

RANDOM_METAL_TURN_DEG = (45.0, 90.0)
"""Random presets: the metal's turn over the sequence, U(a, b) deg, either way."""

RANDOM_METAL_TILT_DEG = 25.0
"""Random presets: the metal's axis tilted U(0, this) deg towards U(0, 360) deg."""

RANDOM_METAL_ROUGHNESS = (0.3, 0.5)
"""Random presets: the metals' GGX roughness, U(a, b): rough enough that the
highlights of the rig's point lights cover more than a few pixels."""

METAL_RADIUS_M = 0.055
"""Mean radius of the turning metal, metres (it is 1.2 times as tall)."""

METAL_LOBES = 3
"""Lobes of the turning metal about its axis (and inlaid stripes, one per lobe)."""

METAL_ROUGHNESS = 0.4
"""GGX roughness of the fixed presets' metals."""

METAL_KD = 0.05
"""Diffuse weight of the metals (their p scales only this small diffuse part)."""

CLOTH_PATCHES = (5, 4)
"""Colour patches across (x) and down (y) the cloth; with the sheet's 131 x 101
vertex grid their edges lie on grid lines."""

CLOTH_COLOURS = {
    "red": (0.8, 0.05, 0.04),
    "green": (0.05, 0.7, 0.08),
    "blue": (0.05, 0.1, 0.8),
    "yellow": (0.85, 0.75, 0.06),
    "cyan": (0.06, 0.7, 0.8),
    "magenta": (0.75, 0.08, 0.65),
    "orange": (0.9, 0.42, 0.05),
    "purple": (0.42, 0.1, 0.7),
    "teal": (0.05, 0.5, 0.42),
    "pink": (0.9, 0.45, 0.6),
    "lime": (0.5, 0.8, 0.12),
    "sky": (0.3, 0.55, 0.9),
    "brown": (0.5, 0.3, 0.14),
    "olive": (0.45, 0.45, 0.1),
    "white": (0.8, 0.8, 0.8),
    "grey": (0.35, 0.35, 0.35),
}
"""Reflectance per light band R, G, B (the chromaticity p times the BRDF scale) of
the cloth's colours: pure (red, green, blue: one band) and mixed (two or three)."""

CLOTH_LAYOUT = (
    ("red", "yellow", "green", "cyan", "blue"),
    ("magenta", "orange", "white", "lime", "purple"),
    ("blue", "teal", "pink", "red", "sky"),
    ("green", "brown", "grey", "olive", "magenta"),
)
"""The colour of each patch, rows down the cloth (y), columns across (x)."""

CLOTH_GLOSS = Material(kd=1.0, specular="ggx", ks=1.0, roughness=0.3, f0=0.04, tint="white")
"""The fixed presets' white-specular dielectric patches (GGX, white lobe)."""


# --------------------------------------------------------------------------- motion
@dataclass(frozen=True)
class RigidMotion:
    """A rigid motion at constant velocity over a sequence, world frame.

    At phase s in [0, 1] (frame f of n: s = f / (n - 1)) a point X of the first
    frame is at ``R(s) (X - centre) + centre + s translation_m``, ``R(s)`` the
    rotation by ``s angle_deg`` about ``axis``.

    Attributes
    ----------
    centre : (3,) the point turned about (in the first frame), metres.
    axis : (3,) rotation axis, any length.
    angle_deg : rotation over the whole sequence, degrees.
    translation_m : (3,) translation of ``centre`` over the whole sequence, metres.
    """

    centre: tuple[float, float, float]
    axis: tuple[float, float, float]
    angle_deg: float
    translation_m: tuple[float, float, float]

    def pose(self, phase: float) -> tuple[np.ndarray, np.ndarray]:
        """(R, t) at ``phase``: X = R X_first + t (R (3, 3), t (3,) metres)."""
        R = axis_angle(self.axis, np.deg2rad(self.angle_deg * phase))
        c = np.asarray(self.centre, float)
        return R, c + phase * np.asarray(self.translation_m, float) - R @ c

    def to_json(self, frames: int) -> dict:
        """The motion and every frame's pose (``frames`` frames), for ``gt/motion.json``."""
        poses = {}
        for f in range(frames):
            R, t = self.pose(f / max(frames - 1, 1))
            poses[f"{f:06d}"] = {"R": R.tolist(), "t": t.tolist()}
        axis = np.asarray(self.axis, float)
        return {
            "note": "world X of frame f = R X of the first frame + t, metres; constant "
            "velocity: rotation by angle_deg about axis through centre, and centre moved by "
            "translation_m, over the whole sequence",
            "centre": [float(x) for x in self.centre],
            "axis": (axis / np.linalg.norm(axis)).tolist(),
            "angle_deg": float(self.angle_deg),
            "translation_m": [float(x) for x in self.translation_m],
            "frames": poses,
        }


@dataclass(frozen=True)
class Sequence:
    """One dynamic scene: its frames' geometry, chromatic frame and description.

    Attributes
    ----------
    name : scene (and chromatic object) name.
    frames : number of frames.
    build : callable frame index -> :class:`~colourhs.synth.scenes.SceneGeometry`.
    chromatic_frame : the frame whose pose the chromatic captures show (an index).
    motion : the rigid motion of a rigid object (``gt/motion.json``); None for the cloth.
    description : scene.json's text (one per scene whatever the preset or draw).
    draw : what a random draw chose, JSON-able ({} for the fixed presets).
    """

    name: str
    frames: int
    build: Callable[[int], sc.SceneGeometry]
    chromatic_frame: int = 0
    motion: RigidMotion | None = None
    description: str = ""
    draw: dict = field(default_factory=dict)

    def meta(self) -> dict:
        """The scene's scene.json."""
        return {
            "chromatic": self.name,
            "chromatic_frame": f"{self.chromatic_frame:06d}",
            "dynamic": True,
            "description": self.description,
        }


DESCRIPTIONS = {
    "moving-toy": "multi-coloured toy dog moving rigidly: 2-5 cm and 10-30 degrees over the "
    "sequence",
    "cloth": "multi-coloured cloth folding and doming: patches of pure and mixed colours, "
    "white-specular dielectric and coloured diffuse",
    "turning-metal": "object of two coloured metals turning about its axis",
}


def _phase(frame: int, frames: int) -> float:
    return frame / max(frames - 1, 1)


def _rigid_frame(base, scale, R0, t0, origin, motion: RigidMotion, phase: float):
    """``base`` placed at scale ``scale``, rotation ``R0`` about ``origin`` and moved to
    ``t0`` (the first frame), then moved by ``motion`` at ``phase``."""
    R, t = motion.pose(phase)
    return sc.transformed(base, scale, R @ R0, R @ np.asarray(t0, float) + t, origin)


# --------------------------------------------------------------------------- toy
@lru_cache(maxsize=2)
def _toy() -> sc.SceneGeometry:
    """The fixed presets' toy (built once per process; read-only)."""
    return sc.toy()


def _bbox_centre(vertices: np.ndarray) -> np.ndarray:
    return (vertices.min(axis=0) + vertices.max(axis=0)) / 2


def fixed_toy_motion() -> RigidMotion:
    """The fixed presets' toy motion, about the toy's bounding-box centre."""
    return RigidMotion(
        tuple(_bbox_centre(_toy().vertices)),
        TOY_MOTION_AXIS,
        TOY_MOTION_ANGLE_DEG,
        TOY_MOTION_TRANSLATION_M,
    )


# --------------------------------------------------------------------------- cloth
def rest_albedo(
    vertices: np.ndarray,
    triangles: np.ndarray,
    rest: np.ndarray,
    texture: Callable[[np.ndarray], np.ndarray],
) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """A ``SceneGeometry.albedo`` that reads ``texture`` at a surface point's rest coordinates.

    A point on triangle ``tri`` of the mesh ``vertices`` (its current, deformed
    shape) has barycentric coordinates in that triangle; the same weights of the
    triangle's corners in ``rest`` give its rest coordinates, so the reflectance
    moves with the surface however the mesh deforms.

    Parameters
    ----------
    vertices : (V, 3) the deformed mesh, metres.
    triangles : (T, 3) its triangles.
    rest : (V, k) every vertex's rest coordinates (for the cloth: x, y on the flat
        cloth, metres).
    texture : callable (N, k) rest coordinates -> (N, 3) reflectance per light band.
    """

    def albedo(points, tri):
        c = triangles[tri]
        a = vertices[c[:, 0]]
        e1, e2, d = vertices[c[:, 1]] - a, vertices[c[:, 2]] - a, points - a
        d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
        p1, p2 = (d * e1).sum(1), (d * e2).sum(1)
        den = d11 * d22 - d12**2
        w1 = (d22 * p1 - d12 * p2) / den
        w2 = (d11 * p2 - d12 * p1) / den
        w0 = 1 - w1 - w2
        r = w0[:, None] * rest[c[:, 0]] + w1[:, None] * rest[c[:, 1]] + w2[:, None] * rest[c[:, 2]]
        return texture(r)

    return albedo


def cloth_patch(rest_xy: np.ndarray, size=(0.26, 0.2)) -> tuple[np.ndarray, np.ndarray]:
    """The patch (column, row) of cloth rest points (N, 2), metres from the cloth's centre."""
    w, h = size
    nx, ny = CLOTH_PATCHES
    i = np.clip(np.floor((rest_xy[:, 0] / w + 0.5) * nx), 0, nx - 1).astype(int)
    j = np.clip(np.floor((rest_xy[:, 1] / h + 0.5) * ny), 0, ny - 1).astype(int)
    return i, j


def cloth(
    phase: float,
    size=(0.26, 0.2),
    tilt_rad: float = 0.15,
    tilt_axis_rad: float = 0.0,
    gloss: Material = CLOTH_GLOSS,
    layout=CLOTH_LAYOUT,
    n=(131, 101),
) -> sc.SceneGeometry:
    """A multi-coloured cloth at ``phase`` in [0, 1], deforming as the white sheet does.

    The mesh is :func:`colourhs.synth.scenes.sheet`'s (same ``size`` in metres,
    tilt, vertex grid ``n`` and height field); the colours are
    :data:`CLOTH_PATCHES` patches of ``layout`` (names of :data:`CLOTH_COLOURS`),
    read at each point's rest coordinates on the flat cloth
    (:func:`rest_albedo`). Patches (i, j) with i + j even are ``gloss`` (a
    white-specular dielectric), the others coloured diffuse (Lambertian).
    """
    base = sc.sheet(
        phase, size=size, n=n, tilt_rad=tilt_rad, tilt_axis_rad=tilt_axis_rad, material=sc.MATTE
    )
    w, h = size
    x, y = np.meshgrid(np.linspace(-w / 2, w / 2, n[0]), np.linspace(-h / 2, h / 2, n[1]))
    rest = np.stack([x, y], -1).reshape(-1, 2)
    colours = np.array([[CLOTH_COLOURS[c] for c in row] for row in layout], float)

    def texture(r):
        i, j = cloth_patch(r, size)
        return colours[j, i]

    i, j = cloth_patch(rest[base.triangles].mean(axis=1), size)
    material_ids = ((i + j) % 2).astype(int)  # 0: gloss, 1: diffuse
    return sc.SceneGeometry(
        "cloth",
        base.vertices,
        base.triangles,
        base.vertex_normals,
        material_ids,
        (gloss, sc.MATTE),
        rest_albedo(base.vertices, base.triangles, rest, texture),
    )


# --------------------------------------------------------------------------- metal
def metal_material(f0_rgb, roughness: float = METAL_ROUGHNESS) -> Material:
    """A coloured metal: GGX with the per-band Fresnel ``f0_rgb``, a small diffuse part."""
    return Material(
        kd=METAL_KD, specular="ggx", ks=1.0, roughness=roughness, tint="fresnel", f0_rgb=f0_rgb
    )


@lru_cache(maxsize=2)
def metal_shape(level: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The turning metal in its own frame: vertices (V, 3) m, triangles (T, 3) and
    each triangle's part (T,): 0 the body, 1 an inlaid stripe.

    A closed star-shaped surface on an icosphere of subdivision ``level``:
    radius :data:`METAL_RADIUS_M` (1 + 0.15 cos(3 phi) (1 - y^2)) with phi the
    azimuth about the object's axis y (lobes at phi = 0, 120, 240 deg, fading
    towards the poles), 1.2 times as tall as wide. The stripes are the
    triangles whose centre has sin(3 phi) > 0.5 (40 deg wide, centred at phi =
    30, 150 and 270 deg; 270 deg faces -z, the rig).
    """
    u, tris = sc._icosphere(level)
    phi = np.arctan2(u[:, 2], u[:, 0])
    r = METAL_RADIUS_M * (1 + 0.15 * np.cos(METAL_LOBES * phi) * (1 - u[:, 1] ** 2))
    v = u * r[:, None] * np.array([1.0, 1.2, 1.0])
    tris = outward_triangles(v, tris)
    c = v[tris].mean(axis=1)
    part = (np.sin(METAL_LOBES * np.arctan2(c[:, 2], c[:, 0])) > 0.5).astype(int)
    return v, tris, part


def turning_metal_base(body_f0, inlay_f0, roughness: float = METAL_ROUGHNESS, level: int = 5):
    """The turning metal in its own frame: body of F0 ``body_f0`` with inlaid stripes of
    F0 ``inlay_f0`` (per band R, G, B). Its chromaticity p (the diffuse part's
    reflectance) is each metal's F0, constant per part, so it moves with the triangles."""
    v, tris, part = metal_shape(level)
    p = np.array([body_f0, inlay_f0], float)
    materials = (
        metal_material(tuple(body_f0), roughness),
        metal_material(tuple(inlay_f0), roughness),
    )
    return sc.SceneGeometry(
        "turning-metal",
        v,
        tris,
        vertex_normals(v, tris),
        part,
        materials,
        lambda _points, tri: p[part[tri]],
    )


def _metal_frame_zero(tilt_rad: float, tilt_axis, turn_deg: float, yaw_deg: float):
    """The metal's first-frame rotation and its turning axis (world): turned by
    ``yaw_deg - turn_deg / 2`` about its own axis y, then tilted by ``tilt_rad`` about
    ``tilt_axis``."""
    tilt = axis_angle(tilt_axis, tilt_rad) if tilt_rad else np.eye(3)
    return tilt @ _yaw(yaw_deg - turn_deg / 2), tilt @ np.array([0.0, 1.0, 0.0])


# --------------------------------------------------------------------------- fixed presets
def fixed_sequences(frames: int) -> tuple[Sequence, ...]:
    """The fixed presets' ``moving-toy``, ``cloth`` and ``turning-metal``, ``frames`` each.

    The toy starts where the static ``toy`` scene is and moves by
    :func:`fixed_toy_motion`; the cloth has the white ``sheet``'s shape; the
    metal (gold body, copper stripes) stands at the world origin, its axis
    leaning :data:`METAL_TILT_DEG` towards the rig, and turns :data:`METAL_TURN_DEG`
    (a stripe faces the rig at mid-sequence). The chromatic captures show the toy
    and the cloth in their first frame, the metal in frame ``(frames - 1) // 2``.
    """
    motion = fixed_toy_motion()
    eye, zero = np.eye(3), np.zeros(3)

    def toy(f):
        return _rigid_frame(_toy(), 1.0, eye, zero, zero, motion, _phase(f, frames))

    R0, axis = _metal_frame_zero(np.deg2rad(METAL_TILT_DEG), (1.0, 0.0, 0.0), METAL_TURN_DEG, 0.0)
    turn = RigidMotion((0.0, 0.0, 0.0), tuple(axis), METAL_TURN_DEG, (0.0, 0.0, 0.0))

    def metal(f):
        base = turning_metal_base(METALS["gold"], METALS["copper"])
        return _rigid_frame(base, 1.0, R0, zero, zero, turn, _phase(f, frames))

    return (
        Sequence("moving-toy", frames, toy, 0, motion, DESCRIPTIONS["moving-toy"]),
        Sequence(
            "cloth", frames, lambda f: cloth(_phase(f, frames)), 0, None, DESCRIPTIONS["cloth"]
        ),
        Sequence(
            "turning-metal", frames, metal, (frames - 1) // 2, turn, DESCRIPTIONS["turning-metal"]
        ),
    )


# --------------------------------------------------------------------------- random presets
def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _all_in_view(rig, points: np.ndarray, motion: RigidMotion, frames: int, margin: float) -> bool:
    """Whether ``points`` (N, 3) of the first frame stay in every camera's view in every frame."""
    for f in range(frames):
        R, t = motion.pose(_phase(f, frames))
        if not in_view(rig, points @ R.T + t, margin):
            return False
    return True


@lru_cache(maxsize=2)
def _metal_hull() -> np.ndarray:
    v = metal_shape()[0]
    return v[ConvexHull(v).vertices]


def _random_toy(rng, rig, rg: RandomRanges, toy: dict, frames: int, statue_level: int, tries: int):
    """The moving toy of a random draw: placed as the static toy is (scale, position,
    yaw), then moved (:data:`RANDOM_TOY_TRANSLATION_M`, :data:`RANDOM_TOY_ROTATION_DEG`),
    redrawn until every frame is in every view; the static toy's materials."""
    shape = _object_shapes(statue_level)["toy"]
    for _ in range(tries):
        s = rng.uniform(*rg.object_scale)
        lateral = rng.uniform(-rg.object_lateral_m, rg.object_lateral_m, 2)
        pos = np.array([*lateral, rng.uniform(-rg.object_depth_m, rg.object_depth_m)])
        yaw = rng.uniform(-rg.object_yaw_deg, rg.object_yaw_deg)
        shift = _unit(rng.normal(size=3)) * rng.uniform(*RANDOM_TOY_TRANSLATION_M)
        axis = _unit(rng.normal(size=3))
        angle = rng.uniform(*RANDOM_TOY_ROTATION_DEG)
        motion = RigidMotion(tuple(pos), tuple(axis), float(angle), tuple(shift))
        R0 = _yaw(yaw)
        first = s * (shape["hull"] - shape["centre"]) @ R0.T + pos
        if _all_in_view(rig, first, motion, frames, rg.margin_px):
            break
    else:
        return None
    base = sc.with_materials(_base_geometry("toy", statue_level), _toy_materials(toy))
    origin = shape["centre"]

    def build(f):
        return _rigid_frame(base, s, R0, pos, origin, motion, _phase(f, frames))

    draw = {
        "scale": s,
        "position": pos.tolist(),
        "yaw_deg": yaw,
        "axis": axis.tolist(),
        "angle_deg": angle,
        "translation_m": shift.tolist(),
    }
    return Sequence("moving-toy", frames, build, 0, motion, DESCRIPTIONS["moving-toy"], draw)


def _random_cloth(rng, sheet: dict, frames: int) -> Sequence:
    """The cloth of a random draw: the drawn sheet's size, tilt and dielectric, the
    patches' colours shuffled."""
    names = [c for row in CLOTH_LAYOUT for c in row]
    order = rng.permutation(len(names))
    nx = CLOTH_PATCHES[0]
    shuffled = [names[k] for k in order]
    layout = tuple(tuple(shuffled[r * nx : (r + 1) * nx]) for r in range(CLOTH_PATCHES[1]))
    gloss = _sheet_material(sheet)

    def build(f):
        return cloth(
            _phase(f, frames),
            size=tuple(sheet["size"]),
            tilt_rad=np.deg2rad(sheet["tilt_deg"]),
            tilt_axis_rad=np.deg2rad(sheet["tilt_axis_deg"]),
            gloss=gloss,
            layout=layout,
        )

    return Sequence("cloth", frames, build, 0, None, DESCRIPTIONS["cloth"], {"layout": layout})


def _random_metal(rng, rig, rg: RandomRanges, frames: int, tries: int) -> Sequence | None:
    """The turning metal of a random draw: two distinct metals of :data:`METALS` (F0
    jittered as the toy's), roughness :data:`RANDOM_METAL_ROUGHNESS`, placed as the
    objects are (scale, position), turned U(0, 360) deg about its axis, tilted and
    turned (:data:`RANDOM_METAL_TILT_DEG`, :data:`RANDOM_METAL_TURN_DEG`)."""
    body, inlay = (str(m) for m in rng.choice(sorted(METALS), 2, replace=False))
    f0 = [
        np.clip(
            np.array(METALS[m]) * (1 + rng.uniform(-rg.metal_f0_jitter, rg.metal_f0_jitter, 3)),
            0,
            1,
        )
        for m in (body, inlay)
    ]
    roughness = float(rng.uniform(*RANDOM_METAL_ROUGHNESS))
    hull = _metal_hull()
    for _ in range(tries):
        s = rng.uniform(*rg.object_scale)
        lateral = rng.uniform(-rg.object_lateral_m, rg.object_lateral_m, 2)
        pos = np.array([*lateral, rng.uniform(-rg.object_depth_m, rg.object_depth_m)])
        tilt = rng.uniform(0, RANDOM_METAL_TILT_DEG)
        towards = np.deg2rad(rng.uniform(0, 360))
        yaw = rng.uniform(0, 360)
        turn = rng.uniform(*RANDOM_METAL_TURN_DEG) * rng.choice([-1.0, 1.0])
        tilt_axis = (np.cos(towards), 0.0, np.sin(towards))
        R0, axis = _metal_frame_zero(np.deg2rad(tilt), tilt_axis, turn, yaw)
        motion = RigidMotion(tuple(pos), tuple(axis), float(turn), (0.0, 0.0, 0.0))
        if _all_in_view(rig, s * hull @ R0.T + pos, motion, frames, rg.margin_px):
            break
    else:
        return None
    base = turning_metal_base(f0[0], f0[1], roughness)
    zero = np.zeros(3)

    def build(f):
        return _rigid_frame(base, s, R0, pos, zero, motion, _phase(f, frames))

    draw = {
        "metals": [body, inlay],
        "f0_rgb": [x.tolist() for x in f0],
        "roughness": roughness,
        "scale": s,
        "position": pos.tolist(),
        "tilt_deg": tilt,
        "yaw_deg": yaw,
        "turn_deg": turn,
    }
    chromatic = (frames - 1) // 2
    return Sequence(
        "turning-metal", frames, build, chromatic, motion, DESCRIPTIONS["turning-metal"], draw
    )


def random_sequences(
    seed: int,
    rig,
    scenes: dict,
    ranges: RandomRanges,
    frames: int,
    statue_level: int = 6,
    tries: int = 300,
) -> tuple[Sequence, ...]:
    """The ``moving-toy``, ``cloth`` and ``turning-metal`` of a random draw.

    Drawn from the seed's own ``dynamic-scenes`` stream, so the rest of the
    seed's draw (rig, board, poses, the static scenes) is what the random
    presets draw.

    Parameters
    ----------
    seed : the dataset's seed.
    rig : the drawn rig (``cameras``, ``width``, ``height``), for the views.
    scenes : the draw's scene description (``RandomDraw.description["scenes"]``):
        the toy's materials and the sheet (size, tilt, dielectric), whose
        ``frames`` frames the draw kept in view.
    ranges : the draw's ranges (object placement, metal roughness and F0 jitter,
        the view margin).
    frames : frames of every sequence.
    statue_level : icosphere subdivision of the objects' shapes (as the draw's).
    tries : placements drawn before giving up.

    Raises
    ------
    RuntimeError
        If no placement keeps the toy or the metal in every view in every frame.
    """
    rng = _stream(seed, "dynamic-scenes")
    toy = _random_toy(rng, rig, ranges, scenes["toy"], frames, statue_level, tries)
    cl = _random_cloth(rng, scenes["sheet"], frames)
    metal = _random_metal(rng, rig, ranges, frames, tries)
    for name, seq in (("moving toy", toy), ("turning metal", metal)):
        if seq is None:
            raise RuntimeError(f"seed {seed}: no {name} in every view in {tries} tries")
    return toy, cl, metal


def scene_meta(sequences: tuple[Sequence, ...], plane: dict) -> dict:
    """scene.json of every scene of a dynamic preset: the held-out ``plane`` (its
    ``plane`` entry) and the sequences."""
    return {"plane": plane} | {s.name: s.meta() for s in sequences}
