"""Synthetic scene geometry: marker board, ChArUco target, white reference, statue, toy, sheet.

Each builder returns a :class:`SceneGeometry`: a triangle mesh in world
coordinates (metres) with smooth vertex normals, a material (reciprocal BRDF)
per triangle and a surface chromaticity (reflectance per light band R, G, B,
the ``p`` of the paper's equation (4)) as a function of the surface point.
The working volume is centred on the world origin; the rig looks along +z.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from colourhs.capture.targets import charuco_black_squares, charuco_markers, charuco_size
from colourhs.common.geometry import axis_angle, outward_triangles, vertex_normals
from colourhs.synth.brdf import Material

WHITE_ALBEDO = 0.8  # reflectance of the board's white and of the white reference
BLACK_ALBEDO = 0.04  # reflectance of the printed markers
SHEET_ALBEDO = 0.7  # the laminated sheet: glossy, so a little darker than the board

MATTE = Material(kd=1.0)


@dataclass(frozen=True)
class SceneGeometry:
    """A renderable, closed-form scene.

    Attributes
    ----------
    vertices : (V, 3) float64 world coordinates, metres.
    triangles : (T, 3) int32 vertex indices, counter-clockwise seen from outside.
    vertex_normals : (V, 3) unit outward normals, for smooth shading.
    material_ids : (T,) int index into ``materials`` per triangle.
    materials : tuple of :class:`~colourhs.synth.brdf.Material`.
    albedo : callable (points (N, 3), triangle ids (N,)) -> (N, 3) reflectance in the
        red, green and blue light bands (the chromaticity p times the BRDF scale).
    """

    name: str
    vertices: np.ndarray
    triangles: np.ndarray
    vertex_normals: np.ndarray
    material_ids: np.ndarray
    materials: tuple[Material, ...]
    albedo: Callable[[np.ndarray, np.ndarray], np.ndarray]


def grid_mesh(nu: int, nv: int, wrap_u: bool = False) -> np.ndarray:
    """Triangles (T, 3) of an nu x nv vertex grid (row-major, u fastest)."""
    cols = nu if wrap_u else nu - 1
    iu, iv = np.meshgrid(np.arange(cols), np.arange(nv - 1))
    a = iv * nu + iu
    b = iv * nu + (iu + 1) % nu
    c = a + nu
    d = b + nu
    tris = np.concatenate([np.stack([a, c, b], -1), np.stack([b, c, d], -1)]).reshape(-1, 3)
    return tris.astype(np.int32)


def merge(name, parts, materials, albedo) -> SceneGeometry:
    """Concatenate parts ``(vertices, triangles, material_id)`` into one scene."""
    verts, tris, mids, off = [], [], [], 0
    for v, t, m in parts:
        verts.append(v)
        tris.append(t + off)
        mids.append(np.full(len(t), m))
        off += len(v)
    v = np.concatenate(verts)
    t = np.concatenate(tris).astype(np.int32)
    return SceneGeometry(
        name, v, t, vertex_normals(v, t), np.concatenate(mids), tuple(materials), albedo
    )


def transformed(
    geom: SceneGeometry,
    scale: float = 1.0,
    R: np.ndarray | None = None,
    t=(0.0, 0.0, 0.0),
    origin=(0.0, 0.0, 0.0),
) -> SceneGeometry:
    """The geometry scaled by ``scale`` and rotated by ``R`` about ``origin``, then moved to ``t``.

    World X' = scale R (X - origin) + t. Materials are kept; the reflectance
    moves with the surface (textures and dirt scale with the object).
    """
    R = np.eye(3) if R is None else np.asarray(R, float)
    o = np.asarray(origin, float)
    tt = np.asarray(t, float)
    v = scale * (geom.vertices - o) @ R.T + tt
    nrm = geom.vertex_normals @ R.T
    inner = geom.albedo

    def albedo(points, tri):
        return inner((points - tt) @ R / scale + o, tri)

    return SceneGeometry(
        geom.name, v, geom.triangles, nrm, geom.material_ids, geom.materials, albedo
    )


def with_materials(geom: SceneGeometry, materials) -> SceneGeometry:
    """The same geometry and reflectance with another material table (same ids)."""
    return SceneGeometry(
        geom.name,
        geom.vertices,
        geom.triangles,
        geom.vertex_normals,
        geom.material_ids,
        tuple(materials),
        geom.albedo,
    )


# --------------------------------------------------------------------------- board
def board_corners(size) -> np.ndarray:
    """Board outline (4, 3) in board coordinates: TL, TR, BR, BL, z = 0."""
    w, h = size
    return np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], float)


def marker_bits(dictionary: str, marker_id: int) -> np.ndarray:
    """The marker's cells (n+2, n+2) as booleans, True = white, border included."""
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    n = d.markerSize + 2
    return cv2.aruco.generateImageMarker(d, int(marker_id), n) > 127


def printed_markers(target: dict) -> dict:
    """The ArUco markers of a printed target, as a rig.json ``board`` block.

    ``target`` is rig.json's ``board`` block (returned as it is) or a ChArUco
    description (``type`` ``"charuco"``, :mod:`colourhs.capture.targets`): then its
    markers in the white squares, their ``dictionary`` and ``marker_length``, and its
    chessboard's ``size``, in the target frame (its chessboard's outer top-left corner
    the origin).
    """
    if target.get("type") != "charuco":
        return target
    return {
        "dictionary": target["dictionary"],
        "marker_length": target["marker_length"],
        "size": list(charuco_size(target)),
        "markers": {str(k): c.tolist() for k, c in charuco_markers(target).items()},
    }


def black_squares(target: dict) -> np.ndarray:
    """The black squares (K, 4) of a printed target, x0, y0, x1, y1 in metres: a ChArUco
    target's chessboard squares without a marker, none (0, 4) for a marker board."""
    if target.get("type") != "charuco":
        return np.zeros((0, 4))
    return charuco_black_squares(target)


def board_reflectance(target: dict, xy_board: np.ndarray) -> np.ndarray:
    """Reflectance (N,) of a printed target at target-frame points (N, 2), metres.

    ``target``: rig.json's ``board`` block or a ChArUco description
    (:func:`printed_markers`). White (:data:`WHITE_ALBEDO`) everywhere but the
    printed ArUco markers' black cells and the black squares (:data:`BLACK_ALBEDO`):
    a matte print. A square covers the points with x0 <= x < x1 and y0 <= y < y1, as
    a marker's cells do.
    """
    board = printed_markers(target)
    out = np.full(len(xy_board), WHITE_ALBEDO)
    L = board["marker_length"]
    x, y = xy_board[:, 0], xy_board[:, 1]
    for mid, centre in board["markers"].items():
        bits = marker_bits(board["dictionary"], int(mid))
        n = bits.shape[0]
        # The points near the marker (a superset, cheap), then the exact test on them.
        near = np.flatnonzero((np.abs(x - centre[0]) < 0.6 * L) & (np.abs(y - centre[1]) < 0.6 * L))
        rel = (xy_board[near] - (np.asarray(centre) - L / 2)) / L * n
        inside = np.all((rel >= 0) & (rel < n), axis=1)
        cells = np.floor(rel[inside]).astype(int)
        out[near[inside]] = np.where(bits[cells[:, 1], cells[:, 0]], WHITE_ALBEDO, BLACK_ALBEDO)
    for x0, y0, x1, y1 in black_squares(target):
        out[(x >= x0) & (x < x1) & (y >= y0) & (y < y1)] = BLACK_ALBEDO
    return out


def board_geometry(target: dict, R_b: np.ndarray, t_b: np.ndarray, name="board") -> SceneGeometry:
    """A printed target at pose (R_b, t_b): world X = R_b X_board + t_b.

    ``target`` is rig.json's board entry (dictionary, marker_length, size,
    markers) or a ChArUco description (:func:`printed_markers`). The white face
    looks along the board's -z axis.
    """
    corners = board_corners(printed_markers(target)["size"]) @ R_b.T + t_b
    tris = np.array([[0, 1, 2], [0, 2, 3]], np.int32)  # normal along board -z (y down)

    def albedo(points, _tri):
        xy = ((points - t_b) @ R_b)[:, :2]
        return np.repeat(board_reflectance(target, xy)[:, None], 3, axis=1)

    return merge(name, [(corners, tris, 0)], [MATTE], albedo)


def white_reference(
    size_m: float = 0.6, z_m: float = 0.0, R: np.ndarray | None = None
) -> SceneGeometry:
    """A large white matte plane facing the rig, for the chromatic reference.

    ``R`` tilts it about its centre (0, 0, z_m).
    """
    h = size_m / 2
    v = np.array([[-h, -h, z_m], [h, -h, z_m], [h, h, z_m], [-h, h, z_m]])
    if R is not None:
        c = np.array([0.0, 0.0, z_m])
        v = (v - c) @ np.asarray(R, float).T + c
    tris = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    return merge("white", [(v, tris, 0)], [MATTE], lambda p, _t: np.full((len(p), 3), WHITE_ALBEDO))


# --------------------------------------------------------------------------- statue
def _icosphere(level: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere by repeated 4-to-1 subdivision."""
    p = (1 + 5**0.5) / 2
    v = np.array(
        [
            [-1, p, 0],
            [1, p, 0],
            [-1, -p, 0],
            [1, -p, 0],
            [0, -1, p],
            [0, 1, p],
            [0, -1, -p],
            [0, 1, -p],
            [p, 0, -1],
            [p, 0, 1],
            [-p, 0, -1],
            [-p, 0, 1],
        ],
        float,
    )
    f = np.array(
        [
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ]
    )
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    for _ in range(level):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = v[uniq].mean(axis=1)
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = inv.reshape(3, -1).T + len(v)  # midpoints of edges 01, 12, 20
        v = np.concatenate([v, mid])
        a, b, c = f.T
        f = np.concatenate(
            [
                np.stack(x, 1)
                for x in ([a, m[:, 0], m[:, 2]], [b, m[:, 1], m[:, 0]], [c, m[:, 2], m[:, 1]], m.T)
            ]
        )
    return v, f.astype(np.int32)


def _bumps(u: np.ndarray, features) -> np.ndarray:
    """Sum of Gaussian bumps on the unit sphere: a * exp(-angle^2 / (2 s^2))."""
    r = np.zeros(len(u))
    for direction, amp, sigma in features:
        d = np.asarray(direction, float)
        d /= np.linalg.norm(d)
        ang = np.arccos(np.clip(u @ d, -1, 1))
        r += amp * np.exp(-(ang**2) / (2 * sigma**2))
    return r


STATUE_FEATURES = (  # (direction, relative amplitude, angular width rad): a monster head
    ((0.0, 0.05, -1.0), 0.22, 0.16),  # snout
    ((0.33, -0.28, -0.9), -0.14, 0.13),  # eye sockets (concave)
    ((-0.33, -0.28, -0.9), -0.14, 0.13),
    ((0.0, -0.45, -0.9), 0.08, 0.25),  # brow
    ((0.12, 0.42, -0.9), -0.1, 0.09),  # mouth (concave groove)
    ((0.0, 0.44, -0.9), -0.11, 0.09),
    ((-0.12, 0.42, -0.9), -0.1, 0.09),
    ((0.45, -0.9, -0.2), 0.35, 0.16),  # horns
    ((-0.45, -0.9, -0.2), 0.35, 0.16),
    ((1.0, -0.1, -0.1), 0.15, 0.2),  # ears
    ((-1.0, -0.1, -0.1), 0.15, 0.2),
)


def statue(
    level: int = 6, radius_m: float = 0.085, seed: int = 7, material: Material | None = None
) -> SceneGeometry:
    """A closed monster-head statue of glossy white plaster with smooth dirt.

    A star-shaped closed surface r(u) = radius (1 + bumps(u) + wrinkles(u)) on
    an icosphere of the given subdivision ``level``, stretched to a head
    shape; eye sockets and mouth are concave. Material (default): diffuse
    plaster with a Blinn-Phong gloss lobe, or ``material``. Chromaticity:
    white with smooth brownish dirt.
    """
    u, tris = _icosphere(level)
    elev = np.arcsin(np.clip(-u[:, 1], -1, 1))
    wrinkles = 0.012 * np.sin(40 * elev) * np.exp(-(((elev - 0.5) / 0.2) ** 2)) * (u[:, 2] < 0)
    r = radius_m * (1 + _bumps(u, STATUE_FEATURES) + wrinkles)
    v = u * r[:, None] * np.array([1.0, 1.15, 0.9])
    tris = outward_triangles(v, tris)
    rng = np.random.default_rng(seed)
    blobs = rng.normal(0, radius_m, (10, 3))
    widths = rng.uniform(0.3, 0.7, 10) * radius_m
    weights = rng.uniform(0.3, 0.8, 10)
    tint = np.array([0.22, 0.32, 0.45])  # dirt absorbs more blue than red

    def albedo(points, _tri):
        d2 = ((points[:, None, :] - blobs[None]) ** 2).sum(-1)
        dirt = np.clip((weights * np.exp(-d2 / (2 * widths**2))).sum(-1), 0, 1)
        return 0.82 * (1 - dirt[:, None] * tint)

    gloss = Material(kd=1.0, specular="blinn_phong", ks=0.25, shininess=30.0)
    return merge("statue", [(v, tris, 0)], [material or gloss], albedo)


# --------------------------------------------------------------------------- toy
def ellipsoid(centre, radii, level: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """A closed ellipsoid mesh (icosphere of subdivision ``level``), outward winding."""
    v, t = _icosphere(level)
    v = v * np.asarray(radii, float) + np.asarray(centre, float)
    return v, outward_triangles(v, t)


def helix_tube(
    start_x, length, coil_radius, tube_radius, turns, centre_yz=(0.0, 0.0), nu=16, nv=700
):
    """A closed tube along a helix about the x axis (the toy's spring torso).

    The tube radius tapers to zero at both ends, closing the surface.
    """
    s = np.linspace(0, 1, nv)
    phi = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    ang = 2 * np.pi * turns * s
    c = np.stack(
        [
            start_x + length * s,
            centre_yz[0] + coil_radius * np.cos(ang),
            centre_yz[1] + coil_radius * np.sin(ang),
        ],
        -1,
    )
    tangent = np.gradient(c, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    radial = c - np.array([c[0, 0], *centre_yz]) * [0, 1, 1]
    radial[:, 0] = 0
    radial -= (radial * tangent).sum(1, keepdims=True) * tangent
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    binormal = np.cross(tangent, radial)
    taper = np.clip(np.minimum(s, 1 - s) / 0.01, 0, 1) ** 0.5
    rr = tube_radius * taper
    v = (
        c[:, None]
        + rr[:, None, None]
        * (
            np.cos(phi)[None, :, None] * radial[:, None]
            + np.sin(phi)[None, :, None] * binormal[:, None]
        )
    ).reshape(-1, 3)
    t = grid_mesh(nu, nv, wrap_u=True)
    return v, outward_triangles(v, t), s


TOY_COLOURS = {
    "red": (0.85, 0.06, 0.04),
    "yellow": (0.85, 0.72, 0.05),
    "green": (0.06, 0.65, 0.1),
    "blue": (0.05, 0.12, 0.8),
    "magenta": (0.75, 0.08, 0.6),
    "brown": (0.55, 0.32, 0.15),
    "metal": (0.92, 0.9, 0.86),
}


SPRING_TURNS = 7.0
SPRING_NU = 16  # vertices around the spring's tube


def toy(plastic: Material | None = None, metal: Material | None = None) -> SceneGeometry:
    """A multi-coloured toy dog like the paper's Slinky.

    Parts: a spring-like helix torso in cycling pure colours (high-frequency
    geometry), specular plastic chest, hips and legs in pure colours, a brown
    head with a fine fur texture and dark eyes, and a mirror-like metal disc on
    a hind leg. Plastics: Lambertian + GGX (roughness 0.35, F0 0.05); metal:
    GGX (roughness 0.15, F0 0.9) with almost no diffuse part. ``plastic`` and
    ``metal`` replace those materials.
    """
    parts, colour_of = [], []
    spring_v, spring_t, spring_s = helix_tube(
        -0.05, 0.09, 0.034, 0.0055, SPRING_TURNS, nu=SPRING_NU
    )
    parts.append((spring_v, spring_t, 0))
    colour_of.append("spring")
    for centre, radii, colour, mat in [
        ((0.075, 0.0, 0.0), (0.03, 0.036, 0.036), "red", 0),  # chest
        ((-0.075, 0.0, 0.0), (0.03, 0.036, 0.036), "blue", 0),  # hips
        ((0.118, -0.03, -0.005), (0.04, 0.034, 0.034), "brown", 0),  # head
        ((0.075, 0.05, -0.02), (0.012, 0.03, 0.012), "green", 0),  # legs
        ((0.075, 0.05, 0.02), (0.012, 0.03, 0.012), "yellow", 0),
        ((-0.075, 0.05, -0.02), (0.012, 0.03, 0.012), "yellow", 0),
        ((-0.075, 0.05, 0.02), (0.012, 0.03, 0.012), "green", 0),
        ((-0.075, 0.045, -0.033), (0.014, 0.014, 0.003), "metal", 1),  # mirror disc
    ]:
        v, t = ellipsoid(centre, radii, level=5 if max(radii) > 0.02 else 4)
        parts.append((v, t, mat))
        colour_of.append(colour)
    # Triangle id ranges of each part, to look up its colour.
    bounds = np.cumsum([0] + [len(t) for _, t, _ in parts])
    ring = ("red", "yellow", "green", "blue", "magenta")
    eyes = np.array([[0.13, -0.045, -0.033], [0.105, -0.045, -0.037]])
    nv_spring = len(spring_s)

    def albedo(points, tri):
        part = np.searchsorted(bounds, tri, side="right") - 1
        out = np.empty((len(points), 3))
        for k, name in enumerate(colour_of):
            sel = part == k
            if not sel.any():
                continue
            if name == "spring":
                # Colour cycles along the helix, one colour per turn.
                # grid_mesh lists one triangle of every quad, then the other.
                row = (tri[sel] % ((nv_spring - 1) * SPRING_NU)) // SPRING_NU
                turn = np.floor(SPRING_TURNS * spring_s[row]).astype(int)
                out[sel] = np.array([TOY_COLOURS[ring[i % len(ring)]] for i in turn])
            else:
                out[sel] = TOY_COLOURS[name]
            if name == "brown":
                p = points[sel]
                fur = 1 + 0.25 * np.sin(2 * np.pi * p[:, 0] / 0.004) * np.sin(
                    2 * np.pi * p[:, 1] / 0.005
                )
                out[sel] *= fur[:, None]
                d = np.min(np.linalg.norm(p[:, None] - eyes[None], axis=-1), axis=1)
                out[sel] = np.where((d < 0.008)[:, None], 0.06, out[sel])
        return out

    plastic = plastic or Material(kd=1.0, specular="ggx", ks=1.0, roughness=0.35, f0=0.05)
    metal = metal or Material(kd=0.05, specular="ggx", ks=1.0, roughness=0.15, f0=0.9)
    return merge("toy", parts, [plastic, metal], albedo)


# --------------------------------------------------------------------------- sheet
def sheet(
    phase: float,
    size=(0.26, 0.2),
    n=(131, 101),
    tilt_rad: float = 0.15,
    tilt_axis_rad: float = 0.0,
    material: Material | None = None,
) -> SceneGeometry:
    """A glossy white laminated sheet folding and doming, at ``phase`` in [0, 1].

    A height field facing the rig: a dome that rises and falls
    (3 cm peak at mid-sequence), a rounded fold whose crease rotates and
    deepens, and a gentle travelling wave; the whole sheet tilted by
    ``tilt_rad`` about an axis in the x-y plane at ``tilt_axis_rad`` from x.
    Material (default): white diffuse with a Ward gloss lobe (alpha 0.18), or
    ``material``.
    """
    w, h = size
    x, y = np.meshgrid(np.linspace(-w / 2, w / 2, n[0]), np.linspace(-h / 2, h / 2, n[1]))
    t = float(phase)
    dome = -0.03 * np.sin(np.pi * t) * np.exp(-((x - 0.03) ** 2 + (y + 0.01) ** 2) / (2 * 0.045**2))
    ang = 0.3 + 0.6 * t
    d = x * np.cos(ang) + y * np.sin(ang) + 0.04
    fold_amp = 0.35 * t**2 * (3 - 2 * t)
    fold = fold_amp * (np.sqrt(d**2 + 0.012**2) - 0.012) * (d > 0)
    wave = 0.004 * np.sin(2 * np.pi * (x / 0.12 + 0.5 * t))
    z = dome + fold + wave - 0.01
    v = np.stack([x, y, z], -1).reshape(-1, 3)
    tris = grid_mesh(n[0], n[1])
    # Tilt the whole sheet a little, as if held.
    if tilt_axis_rad == 0.0:
        c, s = np.cos(tilt_rad), np.sin(tilt_rad)
        v = v @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]]).T
    else:
        v = v @ axis_angle([np.cos(tilt_axis_rad), np.sin(tilt_axis_rad), 0.0], tilt_rad).T
    gloss = material or Material(kd=1.0, specular="ward", ks=0.15, alpha=0.18)
    geom = merge("sheet", [(v, tris, 0)], [gloss], lambda p, _t: np.full((len(p), 3), SHEET_ALBEDO))
    # The sheet faces the rig (-z): make sure its normals do too.
    if geom.vertex_normals[:, 2].mean() > 0:
        geom = merge("sheet", [(v, tris[:, ::-1].copy(), 0)], [gloss], geom.albedo)
    return geom
