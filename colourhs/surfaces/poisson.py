"""Oriented points, visual-hull completion and Poisson meshes (paper section IV-A).

The paper turns each one-sided reconstruction (a depth map with normals in the
reference camera) into a surface mesh by Poisson surface reconstruction [19].
Poisson needs a closed ("watertight") oriented point cloud, so the paper
injects visual-hull vertices where the reconstruction has no data. This module
does the same in four small steps, each a pure function over numpy arrays:

1. :func:`oriented_points` - the depth map's pixels as world points with unit
   normals facing the reference camera;
2. :func:`add_hull_points` - hull vertices away from the data (section IV-A's
   watertightness step);
3. :func:`poisson_mesh` - screened Poisson surface reconstruction (open3d),
   trimmed of its lowest-density vertices;
4. :func:`crop_to_data` - the mesh without the surface Poisson invented far
   from every reconstructed point (hull-only regions, the closing blob).

:func:`frame_mesh` (the Snakemake rule's function) reads a results-contract
depth file and writes ``mesh/<frame>.ply`` (world frame, metres, with vertex
normals). A frame with no surface to mesh (fewer than :data:`MIN_POINTS` pixels
with a depth and a normal, or nothing left after the crop) gets the empty mesh
(:mod:`colourhs.common.ply`), with a warning: in a sequence, one frame without
a reconstruction is a result, not a failure of the whole run. Lengths are
metres throughout.
"""

from __future__ import annotations

import logging
import time
from functools import partial
from pathlib import Path
from typing import NamedTuple

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from colourhs.common.depthfile import DepthMap, as_depth_map
from colourhs.common.geometry import axial_cosine, backproject, pixel_grid
from colourhs.common.ply import load_mesh, write_ply
from colourhs.common.progress import stage

log = logging.getLogger(__name__)

__all__ = [
    "TriMesh",
    "add_hull_points",
    "crop_to_data",
    "frame_mesh",
    "oriented_points",
    "point_spacing",
    "poisson_mesh",
]

#: Hull vertices closer than this many point spacings to the data are dropped (default radius).
HULL_RADIUS_SPACINGS = 5.0
#: Mesh vertices farther than this many point spacings from the data are cropped (default).
CROP_SPACINGS = 4.0
#: ... but never closer than this many Poisson octree voxels (the mesh's own resolution).
CROP_VOXELS = 2.0
#: Hull vertices are used within the data's bounding box grown by this fraction of its extent.
HULL_MARGIN = 0.5
#: open3d's default ratio of the Poisson octree's cube to the points' bounding box.
POISSON_SCALE = 1.1
#: Fewest oriented points Poisson reconstruction is run on; fewer give the empty mesh.
MIN_POINTS = 4


class TriMesh(NamedTuple):
    """A triangle mesh as arrays: vertices (V, 3) metres, triangles (T, 3), unit normals (V, 3)."""

    vertices: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray


def oriented_points(depth_map: DepthMap) -> tuple[np.ndarray, np.ndarray]:
    """World points and outward unit normals of a depth map's reconstructed pixels.

    A pixel (u, v) with z-depth z lies at ``c + d * z / (R d)_z`` on its ray
    ``c + s d`` (c the camera centre, d the unit ray, ``(R d)_z`` its cosine to
    the optical axis). Pixels without a finite positive depth or a finite
    non-zero normal are skipped. Normals are renormalised and flipped where
    they face away from the reference camera (a one-sided reconstruction sees
    only surfaces facing it, so "outward" = towards the camera).

    Parameters
    ----------
    depth_map : DepthMap

    Returns
    -------
    points : ndarray, shape (N, 3)
        World points, metres, in row-major pixel order.
    normals : ndarray, shape (N, 3)
        Unit normals, world frame, ``dot(n, c - X) >= 0``.
    """
    depth = np.asarray(depth_map.depth, float)
    normal = np.asarray(depth_map.normal, float).reshape(-1, 3)
    norm = np.linalg.norm(normal, axis=1)
    ok = (np.isfinite(depth) & (depth > 0)).ravel() & np.isfinite(norm) & (norm > 0)
    uv = pixel_grid(depth_map.width, depth_map.height).reshape(-1, 2)[ok]
    origin, dirs = backproject(uv, depth_map.K, depth_map.dist, depth_map.R, depth_map.t)
    cos_axis = axial_cosine(dirs, depth_map.R)
    points = origin + dirs * (depth.ravel()[ok] / cos_axis)[:, None]
    n = normal[ok] / norm[ok, None]
    facing = np.sum(n * (origin - points), axis=1)
    n[facing < 0] *= -1.0
    return points, n


def point_spacing(points: np.ndarray) -> float:
    """Median distance (metres) from each point to its nearest other point."""
    points = np.asarray(points, float)
    if len(points) < 2:
        raise ValueError("point_spacing needs at least two points")
    d, _ = cKDTree(points).query(points, k=2)
    return float(np.median(d[:, 1]))


def add_hull_points(
    points: np.ndarray,
    normals: np.ndarray,
    hull_vertices: np.ndarray,
    hull_normals: np.ndarray,
    radius_m: float,
    box: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Complete a one-sided oriented point cloud with visual-hull vertices (section IV-A).

    Poisson surface reconstruction expects a closed surface; the paper makes
    its one-sided reconstructions watertight by injecting visual-hull
    vertices. A hull vertex is appended (with the hull's outward normal) when
    it is farther than ``radius_m`` from every reconstructed point, so that
    the hull fills only where there is no data and never competes with it.

    Parameters
    ----------
    points, normals : ndarray, shape (N, 3)
        Reconstructed world points (metres) and unit normals.
    hull_vertices, hull_normals : ndarray, shape (M, 3)
        Hull vertices (metres) and outward unit normals.
    radius_m : float
        Exclusion radius around the data, metres (a few point spacings; the
        hull's distance to the true surface near the data's edges).
    box : pair of ndarray (3,), optional
        Axis-aligned box (lo, hi), metres: hull vertices outside it are not
        added (a narrow-baseline rig's hull reaches far behind the object; that
        part only coarsens Poisson's octree and is cropped away anyway).

    Returns
    -------
    points, normals : ndarray, shape (N + K, 3)
        The data followed by the K kept hull vertices.
    is_hull : ndarray of bool, shape (N + K,)
        True for the appended hull points.
    """
    points = np.asarray(points, float).reshape(-1, 3)
    normals = np.asarray(normals, float).reshape(-1, 3)
    hv = np.asarray(hull_vertices, float).reshape(-1, 3)
    hn = np.asarray(hull_normals, float).reshape(-1, 3)
    if hv.shape != hn.shape:
        raise ValueError(f"hull vertices {hv.shape} and normals {hn.shape} differ in shape")
    if len(points) and len(hv):
        d, _ = cKDTree(points).query(hv, distance_upper_bound=float(radius_m))
        keep = ~np.isfinite(d)  # nothing within radius_m
    else:
        keep = np.ones(len(hv), bool)
    if box is not None:
        keep &= np.all(
            (hv >= np.asarray(box[0], float)) & (hv <= np.asarray(box[1], float)), axis=1
        )
    hn = hn[keep] / np.linalg.norm(hn[keep], axis=1, keepdims=True)
    is_hull = np.concatenate([np.zeros(len(points), bool), np.ones(int(keep.sum()), bool)])
    return np.vstack([points, hv[keep]]), np.vstack([normals, hn]), is_hull


def poisson_voxel(points: np.ndarray, depth: int, scale: float = POISSON_SCALE) -> float:
    """Edge (metres) of the finest Poisson octree cell: largest extent x scale / 2**depth."""
    p = np.asarray(points, float)
    return float(np.ptp(p, axis=0).max() * scale / 2**depth)


def _to_o3d(vertices, triangles) -> o3d.geometry.TriangleMesh:
    return o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.asarray(vertices, float)),
        o3d.utility.Vector3iVector(np.asarray(triangles, np.int32).reshape(-1, 3)),
    )


def _with_normals(mesh: o3d.geometry.TriangleMesh) -> TriMesh:
    mesh.compute_vertex_normals()
    return TriMesh(
        np.asarray(mesh.vertices).copy(),
        np.asarray(mesh.triangles).astype(np.int64),
        np.asarray(mesh.vertex_normals).copy(),
    )


def poisson_mesh(
    points: np.ndarray,
    normals: np.ndarray,
    depth: int = 8,
    density_quantile: float = 0.02,
    scale: float = POISSON_SCALE,
    n_threads: int = 1,
) -> TriMesh:
    """Poisson surface reconstruction [19] of an oriented point cloud.

    Calls open3d's ``TriangleMesh.create_from_point_cloud_poisson`` (screened
    Poisson, Kazhdan and Hoppe) and removes the vertices whose density (the
    octree depth of the samples supporting them) is in the lowest
    ``density_quantile``: the surface Poisson extrapolated far from any point.

    Parameters
    ----------
    points, normals : ndarray, shape (N, 3)
        World points (metres) and unit outward normals.
    depth : int
        Octree depth: the finest cell is ``extent * scale / 2**depth`` (see
        :func:`poisson_voxel`), e.g. 0.86 mm for a 0.2 m object at depth 8.
    density_quantile : float
        Fraction of lowest-density vertices removed (0 keeps all).
    scale : float
        Ratio of the octree's cube to the points' bounding box.
    n_threads : int
        Threads for open3d (-1 = all cores; 1 by default for shared machines).

    Returns
    -------
    TriMesh
        Vertices (metres), triangles and unit vertex normals (outward).
    """
    points = np.asarray(points, float)
    if len(points) < MIN_POINTS:
        raise ValueError(
            f"Poisson reconstruction needs at least {MIN_POINTS} points, got {len(points)}"
        )
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.normals = o3d.utility.Vector3dVector(np.asarray(normals, float))
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        mesh, dens = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
            pcd, depth=int(depth), scale=float(scale), linear_fit=False, n_threads=int(n_threads)
        )
    dens = np.asarray(dens)
    if density_quantile > 0 and len(dens):
        mesh.remove_vertices_by_mask(dens < np.quantile(dens, density_quantile))
    mesh.remove_unreferenced_vertices()
    return _with_normals(mesh)


def crop_to_data(mesh: TriMesh, data_points: np.ndarray, max_dist_m: float) -> TriMesh:
    """Remove the mesh's surface farther than ``max_dist_m`` from every data point.

    Keeps the vertices within ``max_dist_m`` of a reconstructed (non-hull)
    point and the triangles whose three vertices are kept, so the mesh
    carries no surface where there was no data (hull-only sides, Poisson's
    closing of a one-sided cloud).

    Parameters
    ----------
    mesh : TriMesh
    data_points : ndarray, shape (N, 3)
        Reconstructed world points, metres.
    max_dist_m : float
        Distance limit, metres.

    Returns
    -------
    TriMesh
        The cropped mesh (unreferenced vertices removed, normals recomputed).
    """
    d, _ = cKDTree(np.asarray(data_points, float)).query(
        np.asarray(mesh.vertices, float), distance_upper_bound=float(max_dist_m)
    )
    keep = np.isfinite(d)
    tri = np.asarray(mesh.triangles).reshape(-1, 3)
    tri = tri[keep[tri].all(axis=1)]
    used = np.zeros(len(keep), bool)
    used[tri.ravel()] = True
    index = np.cumsum(used) - 1
    out = _to_o3d(np.asarray(mesh.vertices)[used], index[tri])
    return _with_normals(out)


def _empty_mesh(out_ply: str | Path, info: dict, reason: str) -> dict:
    """Write the empty mesh (no vertices, no faces) of a frame with no surface.

    Logs a warning naming the depth file and ``reason``; returns ``info`` with
    ``empty`` True, ``reason`` and zero vertices and triangles.
    """
    log.warning(
        "%s: no surface to mesh, writing the empty mesh %s: %s", info["depth_h5"], out_ply, reason
    )
    write_ply(out_ply, np.zeros((0, 3)), np.zeros((0, 3), np.int32), np.zeros((0, 3)))
    return info | {"vertices": 0, "triangles": 0, "empty": True, "reason": reason}


def frame_mesh(
    depth_h5: str | Path | DepthMap,
    out_ply: str | Path,
    hull_ply: str | Path | None = None,
    poisson_depth: int = 8,
    density_quantile: float = 0.02,
    hull_radius_m: float | None = None,
    crop_dist_m: float | None = None,
    hull_margin: float = HULL_MARGIN,
    n_threads: int = 1,
) -> dict:
    """Mesh one reconstructed frame: depth file -> oriented points (+ hull) -> Poisson PLY.

    The Snakemake rule's function (``results/NAME/<scene>/<variant>/mesh/<frame>.ply``).
    Works for any results-contract depth file, the visual hull's included.
    Logs a line per step at INFO, with the seconds since the start
    (:mod:`colourhs.common.progress`; Poisson itself takes most of the time).

    Parameters
    ----------
    depth_h5 : str, Path or DepthMap
        Results-contract depth file, or the :class:`DepthMap` already read from it
        (:func:`colourhs.common.depthfile.as_depth_map`: read once).
    out_ply : str or Path
        Mesh to write (binary PLY, world frame, metres, vertex normals), atomically.
    hull_ply : str or Path, optional
        Visual-hull mesh (world frame, metres, outward normals) completing the
        one-sided points as in section IV-A; without it Poisson closes the
        cloud on its own and the crop removes that invented surface.
    poisson_depth : int
        Octree depth of :func:`poisson_mesh`.
    density_quantile : float
        Lowest-density fraction of Poisson vertices removed.
    hull_radius_m : float, optional
        :func:`add_hull_points` radius; default ``HULL_RADIUS_SPACINGS`` (5) median
        point spacings.
    crop_dist_m : float, optional
        :func:`crop_to_data` distance; default the larger of ``CROP_SPACINGS`` (4)
        median point spacings and ``CROP_VOXELS`` (2) Poisson voxels.
    hull_margin : float
        Hull vertices are used only inside the data's bounding box grown by this
        fraction of its largest extent on every side (default 0.5).
    n_threads : int
        Threads for Poisson.

    Returns
    -------
    dict
        Counts (points, hull points, vertices, triangles), the spacing, radius,
        crop distance and voxel in metres (None where not reached), the seconds
        taken, ``empty`` and ``reason``. ``empty`` is True when the frame has no
        surface to mesh: fewer than :data:`MIN_POINTS` pixels with a depth and a
        normal, or nothing left after the crop. ``out_ply`` is then the empty mesh
        (a valid PLY with no vertices and no faces), ``reason`` says why (None
        otherwise), the vertex and triangle counts are 0, and a warning naming the
        depth file is logged.

    Raises
    ------
    ValueError
        Naming the file, for a depth file that does not read
        (:func:`colourhs.common.depthfile.read_depth`); ``out_ply`` is then not
        written.
    """
    t0 = time.perf_counter()
    say = partial(stage, log, start=t0)
    dm = as_depth_map(depth_h5)
    say(f"mesh: oriented points of {Path(dm.path).name}")
    points, normals = oriented_points(dm)
    info = {
        "depth_h5": dm.path,
        "hull_ply": None if hull_ply is None else str(hull_ply),
        "points": int(len(points)),
        "hull_points": 0,
        "vertices": 0,
        "triangles": 0,
        "spacing_m": None,
        "hull_radius_m": None,
        "crop_dist_m": None,
        "poisson_depth": int(poisson_depth),
        "poisson_voxel_m": None,
    }
    if len(points) < MIN_POINTS:
        why = f"only {len(points)} pixels with depth and normal (Poisson needs {MIN_POINTS})"
        return _empty_mesh(out_ply, info, why) | {"seconds": time.perf_counter() - t0}
    spacing = point_spacing(points)
    radius = HULL_RADIUS_SPACINGS * spacing if hull_radius_m is None else float(hull_radius_m)
    n_hull = 0
    all_points, all_normals = points, normals
    if hull_ply is not None:
        say(f"mesh: {len(points)} points; adding visual-hull points away from them")
        hv, _, hn = load_mesh(hull_ply)
        lo, hi = points.min(axis=0), points.max(axis=0)
        margin = hull_margin * float(np.max(hi - lo))
        all_points, all_normals, is_hull = add_hull_points(
            points, normals, hv, hn, radius, box=(lo - margin, hi + margin)
        )
        n_hull = int(is_hull.sum())
    voxel = poisson_voxel(all_points, poisson_depth)
    say(f"mesh: Poisson surface of {len(all_points)} points, octree depth {poisson_depth}")
    mesh = poisson_mesh(
        all_points, all_normals, poisson_depth, density_quantile, n_threads=n_threads
    )
    crop = max(CROP_SPACINGS * spacing, CROP_VOXELS * voxel) if crop_dist_m is None else crop_dist_m
    say(f"mesh: cropping {len(mesh.triangles)} triangles to the data")
    mesh = crop_to_data(mesh, points, crop)
    info |= {
        "hull_points": n_hull,
        "spacing_m": spacing,
        "hull_radius_m": radius if hull_ply is not None else None,
        "crop_dist_m": float(crop),
        "poisson_voxel_m": voxel,
    }
    if len(mesh.triangles) == 0:
        why = f"the Poisson mesh is empty after cropping to the data ({crop:.3g} m)"
        return _empty_mesh(out_ply, info, why) | {"seconds": time.perf_counter() - t0}
    write_ply(out_ply, mesh.vertices, mesh.triangles, mesh.normals)
    return info | {
        "vertices": int(len(mesh.vertices)),
        "triangles": int(len(mesh.triangles)),
        "empty": False,
        "reason": None,
        "seconds": time.perf_counter() - t0,
    }
