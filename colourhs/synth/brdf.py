"""Physically based, reciprocal BRDFs for the synthetic Helmholtz-stereopsis renderer.

This module holds the materials: :class:`Material`, a diffuse + specular
mixture with the reflectance ``p_b`` of each light band, and its vectorised
evaluation per point (:func:`evaluate_materials`,
:func:`evaluate_materials_bands`, :func:`albedo_factors`). The BRDF models it
mixes (:func:`lambertian`, :func:`oren_nayar`, :func:`blinn_phong`,
:func:`cook_torrance_ggx`, :func:`ggx_bands`, :func:`ward`) and their
conventions (unit vectors ``n``, ``l``, ``v``; values in ``1/sr``; exactly 0
below the horizon; bit-identical under ``l <-> v``, as Helmholtz stereopsis
needs) are :mod:`colourhs.synth.brdfmodels`, re-exported here.
"""

# ruff: noqa: E741  -- ``l`` (direction to the light) is the conventional, API-mandated name.
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from colourhs.synth.brdfmodels import (
    _param,
    _vectors,
    blinn_phong,
    cook_torrance_ggx,
    ggx_bands,
    lambertian,
    oren_nayar,
    ward,
)

__all__ = [
    "DIFFUSE_MODELS",
    "SPECULAR_MODELS",
    "TINTS",
    "Material",
    "blinn_phong",
    "cook_torrance_ggx",
    "evaluate_materials",
    "albedo_factors",
    "evaluate_materials_bands",
    "ggx_bands",
    "lambertian",
    "oren_nayar",
    "ward",
]

SPECULAR_MODELS = ("none", "blinn_phong", "ggx", "ward")
DIFFUSE_MODELS = ("lambert", "oren_nayar")
#: How a material's reflectance ``p_b`` per light band enters its BRDF (see :class:`Material`).
TINTS = ("albedo", "white", "fresnel")


# --------------------------------------------------------------------------- materials
@dataclass(frozen=True)
class Material:
    """A diffuse + specular mixture BRDF, with the reflectance ``p_b`` of each light band.

    The band-independent BRDF is ``f = kd * diffuse(n, l, v) + ks * spec(n, l, v)``:
    ``diffuse`` is Lambertian (``1 / pi``) or Oren-Nayar (roughness ``sigma``),
    ``spec`` is selected by ``specular`` (``"none"``: no lobe, ``ks`` is ignored).
    How the surface's reflectance ``p_b`` in light band ``b`` (red, green, blue:
    the scene's ``albedo``) enters is the ``tint``:

    * ``"albedo"``: ``f_b = p_b f``, the whole BRDF scaled (separable
      chromaticity; the original materials of the demo scenes);
    * ``"white"``: ``f_b = p_b kd diffuse + ks spec``: a dielectric (plastic,
      paint) whose coloured diffuse part sits under a white specular lobe;
    * ``"fresnel"``: ``f_b = p_b kd diffuse + ks ggx_b``: a metal whose specular
      colour is its Fresnel term, GGX with the per-band ``f0_rgb``
      (``specular`` must be ``"ggx"``).

    Every term is 0 below the horizon and reciprocal to the bit. Units: ``1/sr``.

    Attributes
    ----------
    kd : float
        Diffuse weight.
    specular : str
        One of ``"none"``, ``"blinn_phong"``, ``"ggx"``, ``"ward"``.
    ks : float
        Weight of the specular lobe.
    shininess : float
        Blinn-Phong exponent (used by ``"blinn_phong"``).
    roughness : float
        Perceptual roughness, ``alpha = roughness**2`` (used by ``"ggx"``).
    alpha : float
        Ward RMS slope (used by ``"ward"``).
    f0 : float
        Schlick normal-incidence reflectance (used by ``"ggx"`` unless ``tint`` is
        ``"fresnel"``).
    diffuse : str
        ``"lambert"`` or ``"oren_nayar"``.
    sigma : float
        Oren-Nayar slope-angle deviation, radians (used by ``"oren_nayar"``).
    tint : str
        ``"albedo"``, ``"white"`` or ``"fresnel"`` (see above).
    f0_rgb : tuple of 3 floats or None
        Per-band Schlick reflectance of a ``"fresnel"`` material.

    References
    ----------
    See :func:`lambertian`, :func:`oren_nayar`, :func:`blinn_phong`,
    :func:`cook_torrance_ggx`, :func:`ggx_bands`, :func:`ward`.
    """

    kd: float = 0.5
    specular: str = "none"
    ks: float = 0.0
    shininess: float = 32.0
    roughness: float = 0.5
    alpha: float = 0.2
    f0: float = 0.04
    diffuse: str = "lambert"
    sigma: float = 0.3
    tint: str = "albedo"
    f0_rgb: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.specular not in SPECULAR_MODELS:
            raise ValueError(f"specular must be one of {SPECULAR_MODELS}, got {self.specular!r}")
        if self.diffuse not in DIFFUSE_MODELS:
            raise ValueError(f"diffuse must be one of {DIFFUSE_MODELS}, got {self.diffuse!r}")
        if self.tint not in TINTS:
            raise ValueError(f"tint must be one of {TINTS}, got {self.tint!r}")
        for name in ("kd", "ks", "shininess", "roughness", "alpha", "f0", "sigma"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be finite and non-negative, got {value!r}")
        if self.tint == "fresnel":
            if self.specular != "ggx":
                raise ValueError("a 'fresnel' tint needs the 'ggx' specular model")
            f0 = np.asarray(self.f0_rgb if self.f0_rgb is not None else (), float)
            if f0.shape != (3,) or not np.all(np.isfinite(f0)) or np.any((f0 < 0) | (f0 > 1)):
                raise ValueError(f"f0_rgb must be 3 values in [0, 1], got {self.f0_rgb!r}")
            object.__setattr__(self, "f0_rgb", tuple(float(x) for x in f0))

    def _diffuse(self, n, l, v) -> np.ndarray:
        if self.diffuse == "lambert":
            return lambertian(n, l, v, self.kd)
        return oren_nayar(n, l, v, self.sigma, self.kd)

    def _specular(self, n, l, v) -> np.ndarray:
        if self.specular == "blinn_phong":
            return blinn_phong(n, l, v, self.shininess)
        if self.specular == "ggx":
            return cook_torrance_ggx(n, l, v, self.roughness, self.f0)
        return ward(n, l, v, self.alpha)

    def evaluate(self, n, l, v) -> np.ndarray:
        """Evaluate the band-independent ``kd diffuse + ks spec(n, l, v)`` in ``1/sr``.

        The BRDF of band b is ``p_b`` times this for the ``"albedo"`` tint; for
        ``"white"`` and ``"fresnel"`` use :meth:`evaluate_bands`.

        Parameters
        ----------
        n, l, v : array_like, shape (..., 3)
            Unit normal, unit direction to the light and unit direction to the viewer.

        Returns
        -------
        numpy.ndarray, shape (...,)
            BRDF value in ``1/sr``.

        Raises
        ------
        ValueError
            For a ``"fresnel"`` material (it has no band-independent BRDF).
        """
        if self.tint == "fresnel":
            raise ValueError("a 'fresnel' material has one BRDF per band: use evaluate_bands")
        f = self._diffuse(n, l, v)
        if self.specular == "none":
            return f
        return f + self.ks * self._specular(n, l, v)

    def evaluate_bands(self, n, l, v, albedo, *, factored: bool = False) -> np.ndarray:
        """The BRDF ``f_b`` of each light band (red, green, blue), ``1/sr``.

        Parameters
        ----------
        n, l, v : array_like, shape (..., 3)
            Unit normal, unit direction to the light and unit direction to the viewer.
        albedo : array_like, shape (3,) or (..., 3)
            The surface's reflectance ``p_b`` per band.
        factored : bool
            For the ``"albedo"`` tint, leave out the factor ``p_b`` (return ``f``
            in every band; the caller multiplies by ``p_b``, see
            :func:`albedo_factors`). Other tints ignore it.

        Returns
        -------
        numpy.ndarray, shape (..., 3)
            ``f_b`` per band.
        """
        p = _param(albedo, "albedo")
        if self.tint == "albedo":
            f = self.evaluate(n, l, v)[..., None]
            if factored:
                return np.broadcast_to(f, np.broadcast_shapes(f.shape, p.shape)).copy()
            return p * f
        diffuse = p * self._diffuse(n, l, v)[..., None]
        if self.specular == "none":
            return diffuse
        if self.tint == "white":
            return diffuse + self.ks * self._specular(n, l, v)[..., None]
        return diffuse + self.ks * ggx_bands(n, l, v, self.roughness, self.f0_rgb)


def _material_groups(material_ids, materials, n, l, v):
    ids = np.asarray(material_ids)
    if ids.ndim != 1:
        raise ValueError(f"material_ids must have shape (N,), got {ids.shape}")
    if ids.size and not np.issubdtype(ids.dtype, np.integer):
        raise ValueError("material_ids must be integers")
    ids = ids.astype(np.intp, copy=False)
    count = ids.shape[0]
    n, l, v = _vectors(n, l, v)
    try:
        n = np.broadcast_to(n, (count, 3))
        l = np.broadcast_to(l, (count, 3))
        v = np.broadcast_to(v, (count, 3))
    except ValueError as exc:
        raise ValueError("n, l, v must be broadcastable to (N, 3)") from exc
    if count and (ids.min() < 0 or ids.max() >= len(materials)):
        raise ValueError(f"material ids must lie in [0, {len(materials)})")
    groups = [(int(mid), np.flatnonzero(ids == mid)) for mid in np.unique(ids)]
    return count, groups, n, l, v


def evaluate_materials(material_ids, materials: Sequence[Material], n, l, v) -> np.ndarray:
    """Evaluate per-point materials, vectorised by grouping points per material id.

    ``out[i] = materials[material_ids[i]].evaluate(n[i], l[i], v[i])`` in ``1/sr``.

    Parameters
    ----------
    material_ids : array_like of int, shape (N,)
        Index into ``materials`` for each point.
    materials : sequence of Material
        The material table.
    n, l, v : array_like, shape (N, 3) (or broadcastable to it, e.g. (3,))
        Unit normal, unit direction to the light and unit direction to the viewer.

    Returns
    -------
    numpy.ndarray, shape (N,)
        BRDF values in ``1/sr``.

    Raises
    ------
    ValueError
        If ids are not integers, are out of range, or shapes are inconsistent.

    References
    ----------
    See :class:`Material`.
    """
    count, groups, n, l, v = _material_groups(material_ids, materials, n, l, v)
    out = np.zeros(count, dtype=np.float64)
    for mid, sel in groups:
        out[sel] = materials[mid].evaluate(n[sel], l[sel], v[sel])
    return out


def evaluate_materials_bands(
    material_ids, materials: Sequence[Material], n, l, v, albedo, *, factored: bool = False
) -> np.ndarray:
    """Per-point, per-band BRDFs ``f_b`` (N, 3), grouped per material id.

    ``out[i] = materials[material_ids[i]].evaluate_bands(n[i], l[i], v[i], albedo[i])``;
    with ``factored`` the ``"albedo"``-tint rows leave out ``p_b`` (multiply by
    :func:`albedo_factors` to get ``f_b``). Parameters as
    :func:`evaluate_materials`, plus ``albedo`` (N, 3), the reflectance per band.
    """
    count, groups, n, l, v = _material_groups(material_ids, materials, n, l, v)
    p = np.broadcast_to(np.asarray(albedo, np.float64), (count, 3))
    out = np.zeros((count, 3), dtype=np.float64)
    for mid, sel in groups:
        out[sel] = materials[mid].evaluate_bands(n[sel], l[sel], v[sel], p[sel], factored=factored)
    return out


def albedo_factors(material_ids, materials: Sequence[Material], albedo) -> np.ndarray:
    """Per-band factor (N, 3) that completes ``evaluate_materials_bands(..., factored=True)``.

    ``albedo`` (the reflectance ``p_b``) on points of ``"albedo"``-tint materials,
    1 elsewhere.
    """
    ids = np.asarray(material_ids, np.intp)
    scaled = np.array([m.tint == "albedo" for m in materials], bool)
    p = np.asarray(albedo, np.float64)
    if not len(ids):
        return np.ones((0, 3))
    return np.where(scaled[ids][:, None], p, 1.0)
