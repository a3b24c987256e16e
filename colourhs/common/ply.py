"""PLY meshes: the package's one reader and one writer.

Every mesh the pipeline writes (ground truth, visual hulls, Poisson meshes,
error-coloured meshes) goes through :func:`write_ply`: binary little-endian,
float32 coordinates and normals (0.06 um at 1 m: far below any error this
pipeline measures), 8-bit colours, int32 faces; half the size of open3d's
writer, which stores doubles. Written with numpy because open3d's writers
(legacy and tensor) always store doubles. :func:`load_mesh` reads any
triangle PLY with open3d.

A frame with nothing reconstructed has the **empty mesh**: a valid PLY with no
vertices and no faces, written by :func:`write_ply` like any other. open3d
reports such a file as a failed read (and returns an empty mesh, as it does for
a file that is not a PLY at all), so :func:`is_empty_mesh` reads its header
instead, and :func:`load_mesh` accepts it only when asked (``allow_empty``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from colourhs.capture import CaptureFormatError
from colourhs.common.files import atomic_output, note_read

#: Bytes read to find a PLY header's end (headers are a few hundred bytes).
MAX_HEADER = 65536


def write_ply(
    path: str | Path,
    vertices: np.ndarray,
    triangles: np.ndarray | None = None,
    normals: np.ndarray | None = None,
    colours: np.ndarray | None = None,
) -> Path:
    """Write a binary PLY mesh (or point cloud, without ``triangles``) atomically.

    Parameters
    ----------
    path : the PLY file.
    vertices : (V, 3) world points, metres.
    triangles : (T, 3) vertex indices.
    normals : (V, 3) unit vertex normals.
    colours : (V, 3) RGB, floats in [0, 1] or uint8.
    """
    v = np.asarray(vertices, float).reshape(-1, 3)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    columns = [v]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
        columns.append(np.asarray(normals, float).reshape(-1, 3))
    if colours is not None:
        c = np.asarray(colours)
        if not np.issubdtype(c.dtype, np.integer):
            c = np.round(np.clip(c.astype(float), 0.0, 1.0) * 255.0)
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
        columns.append(c.reshape(-1, 3))
    for name, col in zip(("normals", "colours"), columns[1:], strict=False):
        if len(col) != len(v):
            raise ValueError(f"{path}: {len(v)} vertices but {len(col)} {name}")
    rows = np.empty(len(v), dtype=fields)
    names = iter(rows.dtype.names)
    for col in columns:
        for k in range(3):
            rows[next(names)] = col[:, k]
    faces = np.zeros((0, 3), np.int32) if triangles is None else np.asarray(triangles)
    face_rows = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    face_rows["n"] = 3
    face_rows["v"] = faces.reshape(-1, 3)
    props = "".join(f"property {'float' if t == '<f4' else 'uchar'} {n}\n" for n, t in fields)
    header = (
        f"ply\nformat binary_little_endian 1.0\ncomment colourhs\nelement vertex {len(v)}\n"
        f"{props}element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    with atomic_output(path) as tmp, open(tmp, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(rows.tobytes())
        f.write(face_rows.tobytes())
    return Path(path)


def _element_counts(path: str | Path) -> dict[str, int]:
    """Element name -> count (``vertex``, ``face``...) of a PLY file's header.

    Raises
    ------
    CaptureFormatError
        When the file does not start with a PLY header or a count is not a number.
    """
    with open(path, "rb") as f:
        head = f.read(MAX_HEADER)
    end = head.find(b"end_header")
    if not head.startswith((b"ply\n", b"ply\r")) or end < 0:
        raise CaptureFormatError(path, "not a PLY file (no 'ply' ... 'end_header' header)")
    counts = {}
    for line in head[:end].decode("ascii", "replace").splitlines():
        words = line.split()
        if words[:1] == ["element"]:
            if len(words) != 3 or not words[2].isdigit():
                raise CaptureFormatError(
                    path, f"PLY header line {line.strip()!r} is not 'element NAME COUNT'"
                )
            counts[words[1]] = int(words[2])
    return counts


def is_empty_mesh(path: str | Path) -> bool:
    """Whether a PLY file is the empty mesh: no vertices and no faces (its header says 0).

    The mesh of a frame with nothing reconstructed
    (:func:`colourhs.surfaces.poisson.frame_mesh`) and its error-coloured copy.

    Raises
    ------
    CaptureFormatError
        When the file is not a PLY file.
    """
    counts = _element_counts(path)
    return counts.get("vertex", 0) == 0 and counts.get("face", 0) == 0


def load_mesh(
    path: str | Path, allow_empty: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (V, 3), triangles (T, 3) and unit vertex normals (V, 3) of a PLY mesh.

    Parameters
    ----------
    path : str or Path
        The PLY file.
    allow_empty : bool
        True: the empty mesh (:func:`is_empty_mesh`: a frame with nothing
        reconstructed) gives empty arrays, float (0, 3) vertices and normals and
        int (0, 3) triangles. False (the default): it is an error, as for any mesh
        that must have a surface (a ground truth, a visual hull).

    Returns
    -------
    vertices, triangles, normals : ndarray

    Raises
    ------
    CaptureFormatError
        When no faces are read (a point cloud, a file that is not a PLY; the empty
        mesh unless ``allow_empty``), or, with ``allow_empty``, when the file is not
        a PLY file.
    """
    import open3d as o3d

    note_read(path)
    if allow_empty and is_empty_mesh(path):
        return np.zeros((0, 3)), np.zeros((0, 3), np.int32), np.zeros((0, 3))
    mesh = o3d.io.read_triangle_mesh(str(path))
    if len(mesh.triangles) == 0:
        raise CaptureFormatError(path, "not a triangle mesh (no faces read)")
    if not mesh.has_vertex_normals():
        mesh.compute_vertex_normals()
    return np.asarray(mesh.vertices), np.asarray(mesh.triangles), np.asarray(mesh.vertex_normals)
