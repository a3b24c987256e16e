"""A 3D look at a scene's results in the report, offline: meshes embedded in the page.

:func:`pack_mesh` packs a coloured triangle mesh for the page's viewer
(``colourhs/report/templates/report.html``: a 2-D canvas, drag to turn, painter's
algorithm with Lambert shading, nothing fetched at view time): vertices as
int16 on the mesh's bounding cube, colours uint8, triangles uint32, each
base64. :func:`mesh_payload` reads an error-coloured PLY, simplifies it to at
most ``max_triangles`` (:func:`simplify`: open3d's vertex clustering, then its
quadric decimation, vertex colours kept) and packs it; :func:`scene_views`
does so for the first frame of every variant of a scene (results contract:
``<variant>/eval/<frame>.ply``), leaving out, with a warning, a variant whose
mesh is the empty mesh (nothing reconstructed: nothing to turn and look at).
"""

from __future__ import annotations

import base64
import logging
from pathlib import Path

import numpy as np

from colourhs.common.files import note_read
from colourhs.common.ply import is_empty_mesh
from colourhs.common.progress import bar
from colourhs.report.provenance import result_files

log = logging.getLogger(__name__)

__all__ = ["MAX_TRIANGLES", "mesh_payload", "pack_mesh", "scene_views", "simplify"]

#: Triangles per embedded mesh: about 60 kB of page per mesh (80 kB as base64).
MAX_TRIANGLES = 3000

#: A mesh of more than this many times the budget is first clustered to about
#: that many triangles: quadric decimation then works on a mesh of its own
#: output's order of size (its cost grows with the input), and keeps its quality
#: for the final step.
PRE_FACTOR = 10


def _b64(a: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(a).tobytes()).decode("ascii")


def pack_mesh(
    vertices: np.ndarray,
    triangles: np.ndarray,
    colours: np.ndarray | None = None,
    rotation: np.ndarray | None = None,
) -> dict:
    """A mesh for the report's viewer.

    Parameters
    ----------
    vertices : (V, 3) float, metres (world frame).
    triangles : (T, 3) int, vertex indices.
    colours : (V, 3) float in [0, 1], or None (grey).
    rotation : (3, 3) world-to-camera rotation, or None: the viewer starts looking
        along this camera's z axis (image x right, y down), e.g. the reference
        camera's, as in the depth maps.

    Returns
    -------
    dict
        ``v`` (base64 little-endian int16, V x 3: coordinates about the bounding
        box's centre in units of ``size_m`` / 65534), ``c`` (base64 uint8, V x 3),
        ``t`` (base64 little-endian uint32, T x 3), ``nv``, ``nt`` and ``size_m``
        (the largest side of the bounding box, metres).
    """
    v = np.asarray(vertices, float).reshape(-1, 3)
    if rotation is not None:
        v = v @ np.asarray(rotation, float).T
    lo, hi = v.min(axis=0), v.max(axis=0)
    size = float(max(np.max(hi - lo), 1e-9))
    q = np.round((v - (lo + hi) / 2) / size * 65534).astype("<i2")
    c = np.full(v.shape, 0.7) if colours is None else np.asarray(colours, float).reshape(-1, 3)
    t = np.asarray(triangles).reshape(-1, 3).astype("<u4")
    return {
        "v": _b64(q),
        "c": _b64(np.round(np.clip(c, 0, 1) * 255).astype(np.uint8)),
        "t": _b64(t),
        "nv": len(v),
        "nt": len(t),
        "size_m": size,
    }


def _cluster_voxel(mesh, n_triangles: int) -> float:
    """Voxel edge (metres) giving about ``n_triangles`` on ``mesh``'s surface: a
    regular triangulation of area A with edge v has about 2 A / v**2 triangles.
    At least 1e-4 of the bounding box (a mesh of zero area)."""
    extent = float(np.max(mesh.get_max_bound() - mesh.get_min_bound()))
    return max(float(np.sqrt(2.0 * mesh.get_surface_area() / n_triangles)), 1e-4 * extent)


def simplify(mesh, max_triangles: int = MAX_TRIANGLES):
    """An open3d ``TriangleMesh`` simplified to at most ``max_triangles``, colours kept.

    Beyond the paper (presentation only): a mesh over ``PRE_FACTOR`` times the
    budget is first clustered onto voxels sized for that many triangles
    (:func:`_cluster_voxel`; vertex colours averaged), then reduced by quadric
    decimation. Quadric decimation stops short of the budget on a
    non-manifold mesh (a noisy ML surface, or the clustering's output); the
    rest is clustered again, the voxel grown by 1.25 each time, until it fits.
    """
    if len(mesh.triangles) <= max_triangles:
        return mesh
    if len(mesh.triangles) > PRE_FACTOR * max_triangles:
        mesh = mesh.simplify_vertex_clustering(_cluster_voxel(mesh, PRE_FACTOR * max_triangles))
    mesh = mesh.simplify_quadric_decimation(target_number_of_triangles=max_triangles)
    voxel = _cluster_voxel(mesh, max_triangles)
    while len(mesh.triangles) > max_triangles:
        mesh = mesh.simplify_vertex_clustering(voxel)
        voxel *= 1.25
    return mesh


def mesh_payload(
    ply: str | Path, max_triangles: int = MAX_TRIANGLES, rotation: np.ndarray | None = None
) -> dict | None:
    """:func:`pack_mesh` of the PLY mesh ``ply`` (vertex colours kept), simplified to
    at most ``max_triangles`` triangles (:func:`simplify`); None for the empty mesh
    (:func:`colourhs.common.ply.is_empty_mesh`: nothing reconstructed).

    Raises
    ------
    ValueError
        When ``ply`` is not a PLY file or has vertices but no faces.
    """
    import open3d as o3d

    note_read(ply)
    if is_empty_mesh(ply):
        return None
    mesh = o3d.io.read_triangle_mesh(str(ply))
    if not mesh.has_triangles():
        raise ValueError(f"{ply}: not a triangle mesh (no faces read)")
    mesh = simplify(mesh, max_triangles)
    colours = np.asarray(mesh.vertex_colors) if mesh.has_vertex_colors() else None
    return pack_mesh(
        np.asarray(mesh.vertices), np.asarray(mesh.triangles), colours, rotation=rotation
    )


def scene_views(
    results_dir: str | Path,
    scene: str,
    max_triangles: int = MAX_TRIANGLES,
    rotation: np.ndarray | None = None,
) -> dict[str, dict]:
    """Variant -> :func:`mesh_payload` of its first frame's error-coloured mesh
    (``<variant>/eval/<frame>.ply``), variants in the paper's order; {} when none.
    A variant whose mesh is empty (nothing reconstructed) is left out, with a
    warning. A bar over the meshes (:func:`colourhs.common.progress.bar`)."""
    files = result_files(results_dir, scene)
    plys = {v: k["error-coloured mesh"][0] for v, k in files.items() if k["error-coloured mesh"]}
    label = f"report: 3D views of {scene}"
    views = {}
    for v, ply in bar(plys.items(), label, len(plys), unit="mesh"):
        payload = mesh_payload(ply, max_triangles, rotation)
        if payload is None:
            log.warning("%s: empty mesh (nothing reconstructed): no 3D view of %s", ply, v)
        else:
            views[v] = payload
    return views
