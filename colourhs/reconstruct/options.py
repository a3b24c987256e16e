"""The tuning options of a frame's reconstruction (:func:`.frame.reconstruct`)."""

from __future__ import annotations

from dataclasses import dataclass

WORKING_RADIUS = 0.25  # depth hypotheses: the working depth +- this fraction of it
"""Why ``WORKING_RADIUS`` holds on any rig: it is relative to the working
distance, so a rig twice as far from its objects searches twice as deep.
A rig's common volume (where the three views overlap) grows with its
distance, and so do the poses a user gives the board and the objects: a
board slanted up to 45 deg and held a tenth of the working depth D off the
fixation depth reaches about a fifth of D in front of it, which a range
fixed in metres cuts off on a far rig. A scene beyond it is reconstructed
only where the hull gives the range (``depth_from_hull``) or
``depth_range`` is given.
"""
MAX_SIGMA = 0.05  # depths less certain than this fraction of themselves are flagged
"""Why ``MAX_SIGMA`` holds on any rig: relative to the depth, like the pixel
footprint, the disparity step and the working radius, so a rig twice as far
tolerates twice the error; a depth uncertain by 5 % of itself (a fifth of
the depth range searched) no longer tells a surface from the space around
it. A user who needs more sets ``max_sigma_mm``."""


@dataclass(frozen=True)
class ReconstructOptions:
    """The reconstruction's tuning options (keywords of :func:`reconstruct`).

    Attributes
    ----------
    n_labels : number of depth hypotheses.
    working_radius : half the depth range as a fraction of the working depth
        (see ``WORKING_RADIUS``).
    working_radius_m : the same in metres, instead of ``working_radius``
        (a fixed length fits one rig only).
    alpha : weight of the data term in the Bayesian energy.
    tau : truncation of the depth-normal prior, in labels.
    refine : continuous refinement after the Bayesian labelling.
    data_weight : weight of the discrete solution in the initial surface
        (the normal integration that starts the refinement).
    max_cost : pixels whose chosen hypothesis costs more are left out.
    cost_scale : the Bayesian data term is ``min(cost / cost_scale, 1 / cost_scale)``
        (sigma_3 / sigma_2 in units of its typical noise level).
    edge_m, refine_passes : the initial surface's edge threshold (metres)
        and number of passes (each re-evaluates the normals).
    min_component : connected groups of valid pixels smaller than this (e.g.
        the white cells inside a marker, cut off by its black ones) are left
        out of the Bayesian result; default (None) 0.2 % of the image; 0 keeps all
        (:func:`min_component_px`).
    erode_px : the Bayesian result's mask is eroded by this many pixels;
        default 1 per 320 pixels of image width (at least 1).
    link_m : neighbours within this distance of each other's tangent plane
        belong to one surface (small unlinked pieces are left out).
    surface_iterations, spline_px : the final refinement
        (:func:`colourhs.reconstruct.bayes.refine.refine_surface`):
        Levenberg-Marquardt steps before and after its depth search, and the
        spline control spacing (default 1/120 of the width,
        :func:`colourhs.reconstruct.bayes.spline.default_spacing`).
    blur_px : Gaussian blur of the Helmholtz sides before sampling, pixels
        (ML HS's continuous step and the refinement; default
        :data:`colourhs.reconstruct.sides.BLUR_PX`, see
        :func:`colourhs.reconstruct.sides.side_maps`).
    max_sigma_mm : a depth whose 1-sigma uncertainty (``depth_sigma``) exceeds
        this many millimetres is flagged ``uncertain`` and left out of the
        result's mask and depth, not silently kept; the accuracy the user
        asks for. Default (None) ``MAX_SIGMA`` of the depth.
    """

    n_labels: int = 192
    working_radius: float = WORKING_RADIUS
    working_radius_m: float | None = None
    alpha: float = 0.35
    tau: float = 30.0
    refine: bool = True
    data_weight: float = 0.01
    max_cost: float = 0.5
    cost_scale: float = 0.05
    edge_m: float = 0.02
    refine_passes: int = 3
    min_component: int | None = None
    erode_px: int | None = None
    link_m: float = 0.002
    surface_iterations: int = 3
    spline_px: float | None = None
    blur_px: float | None = None
    max_sigma_mm: float | None = None


def min_component_px(min_component: int | None, shape: tuple[int, int]) -> int:
    """Smallest connected group of valid pixels the Bayesian result keeps:
    ``min_component``, or 0.2 % of the image when it is None (0 keeps all)."""
    H, W = shape
    return int(0.002 * H * W if min_component is None else min_component)
