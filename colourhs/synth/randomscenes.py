"""The scenes of a random draw: the objects' placement and materials, the sheet, the lights.

:func:`_draw_scenes` places the statue and the toy (scale, position, yaw) and
draws their materials, the dynamic sheet, the chromatic light's position and
the white reference's tilt, from the seed's ``geometry`` stream;
:func:`_builders` turns that description into the scene builders of a
:class:`~colourhs.synth.randomrig.RandomDraw`. The ranges are the table of
:mod:`colourhs.synth.randomrig`.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.spatial import ConvexHull

from colourhs.synth import scenes as sc
from colourhs.synth.brdf import Material
from colourhs.synth.poses import in_view
from colourhs.synth.randomranges import METALS


# --------------------------------------------------------------------------- scenes
def _hull_points(vertices: np.ndarray) -> np.ndarray:
    return vertices[ConvexHull(vertices).vertices]


@lru_cache(maxsize=4)
def _base_geometry(name: str, statue_level: int) -> sc.SceneGeometry:
    """The statue or toy in its own frame (built once per process; treat as read-only)."""
    return sc.statue(statue_level) if name == "statue" else sc.toy()


@lru_cache(maxsize=4)
def _object_shapes(statue_level: int) -> dict:
    """Convex-hull points and bounding-box centres of the statue and toy, object frame."""
    out = {}
    for name in ("statue", "toy"):
        v = _base_geometry(name, statue_level).vertices
        out[name] = {"hull": _hull_points(v), "centre": (v.min(axis=0) + v.max(axis=0)) / 2}
    return out


def _yaw(deg: float) -> np.ndarray:
    return sc.axis_angle([0.0, 1.0, 0.0], np.deg2rad(deg))


def _place(rng, view, rg, shape, tries=300) -> dict | None:
    for _ in range(tries):
        s = rng.uniform(*rg.object_scale)
        pos = np.array(
            [
                *rng.uniform(-rg.object_lateral_m, rg.object_lateral_m, 2),
                rng.uniform(-rg.object_depth_m, rg.object_depth_m),
            ]
        )
        yaw = rng.uniform(-rg.object_yaw_deg, rg.object_yaw_deg)
        pts = s * (shape["hull"] - shape["centre"]) @ _yaw(yaw).T + pos
        if in_view(view, pts, rg.margin_px):
            return {"scale": s, "position": pos, "yaw_deg": yaw, "origin": shape["centre"]}
    return None


def _tilt(rng, max_deg) -> tuple[float, float]:
    """A tilt angle U(0, max) and the direction of its axis U(0, 360), degrees."""
    return float(rng.uniform(0, max_deg)), float(rng.uniform(0, 360))


def _tilt_matrix(angle_deg, axis_deg) -> np.ndarray:
    a = np.deg2rad(axis_deg)
    return sc.axis_angle([np.cos(a), np.sin(a), 0.0], np.deg2rad(angle_deg))


def _draw_scenes(rng, view, rg, geo, shapes, sheet_frames) -> dict | None:
    statue = _place(rng, view, rg, shapes["statue"])
    if statue is None:
        return None
    toy = _place(rng, view, rg, shapes["toy"])
    if toy is None:
        return None
    kind = str(rng.choice(["plaster", "dielectric", "rough_diffuse"]))
    statue["material"] = kind
    statue["roughness"] = float(rng.uniform(*rg.ggx_roughness))
    statue["f0"] = float(rng.uniform(*rg.dielectric_f0))
    statue["sigma"] = float(rng.uniform(*rg.oren_nayar_sigma))
    metal = str(rng.choice(sorted(METALS)))
    toy["plastic_roughness"] = float(rng.uniform(*rg.ggx_roughness))
    toy["plastic_f0"] = float(rng.uniform(*rg.dielectric_f0))
    toy["metal"] = metal
    toy["metal_roughness"] = float(rng.uniform(*rg.metal_roughness))
    jitter = 1 + rng.uniform(-rg.metal_f0_jitter, rg.metal_f0_jitter, 3)
    toy["metal_f0_rgb"] = np.clip(np.array(METALS[metal]) * jitter, 0, 1)
    sheet = None
    for _ in range(100):
        width = rng.uniform(*rg.sheet_width_m)
        tilt, axis = _tilt(rng, rg.sheet_tilt_deg)
        cand = {"size": [width, width * 0.2 / 0.26], "tilt_deg": tilt, "tilt_axis_deg": axis}
        frames = [
            _sheet(cand, f / max(sheet_frames - 1, 1), material=None) for f in range(sheet_frames)
        ]
        if all(in_view(view, _hull_points(g.vertices), rg.margin_px) for g in frames):
            sheet = cand
            break
    if sheet is None:
        return None
    sheet["roughness"] = float(rng.uniform(*rg.ggx_roughness))
    sheet["f0"] = float(rng.uniform(*rg.dielectric_f0))
    sheet["frames"] = sheet_frames
    rho = rng.uniform(*rg.chromatic_offset_m)
    az = np.deg2rad(rng.uniform(0, 360))
    z = -rng.uniform(*rg.chromatic_depth_rel) * geo["distance"]
    chromatic = np.array([rho * np.cos(az), rho * np.sin(az), z])
    white_tilt, white_axis = _tilt(rng, rg.white_tilt_deg)
    return {
        "statue": statue,
        "toy": toy,
        "sheet": sheet,
        "chromatic_light": chromatic,
        "white": {
            "tilt_deg": white_tilt,
            "tilt_axis_deg": white_axis,
            "size_m": 6 * geo["half_width"],
        },
    }


def _sheet(desc, phase, material):
    return sc.sheet(
        phase,
        size=tuple(desc["size"]),
        tilt_rad=np.deg2rad(desc["tilt_deg"]),
        tilt_axis_rad=np.deg2rad(desc["tilt_axis_deg"]),
        material=material,
    )


def _statue_material(d) -> Material:
    if d["material"] == "plaster":
        return Material(kd=1.0, specular="blinn_phong", ks=0.25, shininess=30.0)
    if d["material"] == "dielectric":
        return Material(
            kd=1.0, specular="ggx", ks=1.0, roughness=d["roughness"], f0=d["f0"], tint="white"
        )
    return Material(kd=1.0, diffuse="oren_nayar", sigma=d["sigma"])


def _toy_materials(ty: dict) -> list[Material]:
    """The toy's drawn plastic and metal (``ty``: the draw's ``toy`` entry)."""
    plastic = Material(
        kd=1.0,
        specular="ggx",
        ks=1.0,
        roughness=ty["plastic_roughness"],
        f0=ty["plastic_f0"],
        tint="white",
    )
    metal = Material(
        kd=0.05,
        specular="ggx",
        ks=1.0,
        roughness=ty["metal_roughness"],
        tint="fresnel",
        f0_rgb=tuple(ty["metal_f0_rgb"]),
    )
    return [plastic, metal]


def _sheet_material(sh: dict) -> Material:
    """The sheet's drawn white-specular dielectric (``sh``: the draw's ``sheet`` entry)."""
    return Material(
        kd=1.0, specular="ggx", ks=1.0, roughness=sh["roughness"], f0=sh["f0"], tint="white"
    )


def _builders(desc: dict, geo: dict, statue_level: int) -> dict:
    st, ty, sh, wh = desc["statue"], desc["toy"], desc["sheet"], desc["white"]

    def statue():
        g = sc.with_materials(_base_geometry("statue", statue_level), [_statue_material(st)])
        return sc.transformed(g, st["scale"], _yaw(st["yaw_deg"]), st["position"], st["origin"])

    def toy():
        g = sc.with_materials(_base_geometry("toy", statue_level), _toy_materials(ty))
        return sc.transformed(g, ty["scale"], _yaw(ty["yaw_deg"]), ty["position"], ty["origin"])

    sheet_material = _sheet_material(sh)

    def sheet(phase):
        return _sheet(sh, phase, sheet_material)

    def white():
        return sc.white_reference(
            wh["size_m"], 0.0, _tilt_matrix(wh["tilt_deg"], wh["tilt_axis_deg"])
        )

    return {"white": white, "statue": statue, "toy": toy, "sheet": sheet}
