"""Ground truth of a synthetic dataset beyond its meshes: mu maps and board poses.

:func:`true_mu_maps` gives ``gt/photometric.h5``'s maps of a rig model;
:func:`true_poses_csv` turns a dataset's ``gt/board_poses.json`` into a
marker-poses table. Re-exported by :mod:`colourhs.synth.synthesise`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from colourhs.synth.image_formation import camera_rays
from colourhs.synth.simulated_rig import COLOURS, RigModel


def true_mu_maps(rig: RigModel) -> dict[str, np.ndarray]:
    """Ground-truth mu = rho / sigma (eq. 2) per Helmholtz camera, on pixel centres.

    Keys are ``"<camera>/<channel colour>"`` for every channel that records
    another camera's light; values are float32 (height, width).

    The light's radiance is taken towards the ray's point 0.8 m from the
    camera, or, for a light off the lens (``light_offset`` not zero), at the
    camera's distance to the world origin (where the scenes are): a light
    beside the lens sees the points of one ray in directions that differ by
    about offset x (1/d1 - 1/d2) rad between depths d1 and d2, so its mu is
    exact at that depth only.
    """
    colours = [c.light_colour for c in rig.cameras]
    out = {}
    for i, cam in enumerate(rig.cameras):
        rays = camera_rays(cam, rig.width, rig.height, supersample=1)
        # 0.8 m for collocated lights, whose mu does not depend on the depth (their
        # maps stay as they were); the scene's depth for the others.
        depth = float(np.linalg.norm(cam.centre)) if np.any(cam.light_offset) else 0.8
        for colour in colours:
            if colour == cam.light_colour:
                continue
            ch = COLOURS.index(colour)
            mu = rig.helmholtz_mu(i, ch, rays.xy, rays.origin + depth * rays.directions)
            out[f"{cam.name}/{colour}"] = mu.reshape(rig.height, rig.width).astype(np.float32)
    return out


def true_poses_csv(dataset_dir: str | Path, out_csv: str | Path) -> Path:
    """A marker-poses table (``R00..R22``, ``t_x/y/z``) from a synthetic dataset's true poses.

    Reads ``gt/board_poses.json``; the rows are the ``photometric/`` poses in
    name order, so a stage fed this table instead of
    :func:`colourhs.calibration.markers.marker_poses`'s is isolated from pose errors.
    """
    root = Path(dataset_dir)
    poses = json.loads((root / "gt" / "board_poses.json").read_text())
    rows = []
    for name in sorted(p.name for p in (root / "photometric").iterdir()):
        R, t = np.array(poses[name]["R"]), np.array(poses[name]["t"])
        row = {"pose": name} | {f"R{i}{j}": R[i, j] for i in range(3) for j in range(3)}
        rows.append(row | {"t_x": t[0], "t_y": t[1], "t_z": t[2]})
    import pandas as pd

    pd.DataFrame(rows).to_csv(out_csv, index=False)
    return Path(out_csv)
