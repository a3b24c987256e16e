"""The BRDF models: Lambertian, Oren-Nayar, Blinn-Phong, Cook-Torrance GGX and Ward.

Helmholtz stereopsis relies on the reciprocity of the BRDF,
``f(n, l, v) == f(n, v, l)``, so every model here is written so that swapping the
light and viewer directions gives *bit-identical* results (all quantities are
built from symmetric expressions such as ``n.l + n.v``, ``(n.l) * (n.v)`` and
``l.v``).

Conventions
-----------
* ``n``, ``l``, ``v`` are ``(..., 3)`` **unit** vectors (surface normal, direction
  from the surface point *to* the light, direction *to* the viewer). They are
  broadcast against each other; they are not re-normalised.
* Model parameters may be scalars or ``(...,)`` arrays broadcastable against the
  leading shape of the vectors.
* Every function returns a float64 ``(...,)`` array of BRDF values in ``1/sr``.
* Where ``n.l <= 0`` or ``n.v <= 0`` the BRDF is exactly ``0`` (opaque surfaces,
  no transmission). Cosines that appear in denominators are clamped to
  ``_EPS`` so that no NaN/inf is ever produced.
* The half vector is ``h = (l + v) / |l + v|``. For unit ``l`` and ``v`` one has
  ``|l + v| = sqrt(2 + 2 l.v)``, hence ``n.h = (n.l + n.v) / sqrt(2 + 2 l.v)`` and
  ``h.v = h.l = sqrt((1 + l.v) / 2)``; these symmetric identities are used
  directly.

The materials that mix these models per light band are :mod:`colourhs.synth.brdf`,
which re-exports them.
"""

# ruff: noqa: E741  -- ``l`` (direction to the light) is the conventional, API-mandated name.
from __future__ import annotations

import numpy as np

__all__ = [
    "blinn_phong",
    "cook_torrance_ggx",
    "ggx_bands",
    "lambertian",
    "oren_nayar",
    "ward",
]

#: Smallest value a cosine (or product of cosines) may take inside a division.
_EPS = 1e-12
#: Smallest microfacet slope width ``alpha`` (GGX, Ward); keeps lobes finite.
_ALPHA_MIN = 1e-4


# --------------------------------------------------------------------------- helpers
def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Broadcast dot product over the last axis with a fixed, symmetric summation order."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _vectors(n, l, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = np.asarray(n, dtype=np.float64)
    l = np.asarray(l, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    for name, arr in (("n", n), ("l", l), ("v", v)):
        if arr.ndim == 0 or arr.shape[-1] != 3:
            raise ValueError(f"{name} must have shape (..., 3), got {arr.shape}")
    return n, l, v


def _cross_norm2(n, l, v) -> np.ndarray:
    """``|n x l + n x v|^2`` (= ``|l + v|^2 |n x h|^2``) over the last axis.

    The same products, differences and sums in the same order as
    ``_dot(c, c)`` with ``c = np.cross(n, l) + np.cross(n, v)`` (NumPy forms
    component i as ``a[j] b[k] - a[k] b[j]``), so bit-identical to it, without
    ``np.cross``'s axis moves and stacked copies, which the renderer would pay
    for on every pixel of every image.
    """
    n0, n1, n2 = n[..., 0], n[..., 1], n[..., 2]
    c0 = (n1 * l[..., 2] - n2 * l[..., 1]) + (n1 * v[..., 2] - n2 * v[..., 1])
    c1 = (n2 * l[..., 0] - n0 * l[..., 2]) + (n2 * v[..., 0] - n0 * v[..., 2])
    c2 = (n0 * l[..., 1] - n1 * l[..., 0]) + (n0 * v[..., 1] - n1 * v[..., 0])
    return c0 * c0 + c1 * c1 + c2 * c2


def _geometry(n, l, v) -> dict[str, np.ndarray]:
    """Symmetric geometric terms shared by all models.

    Returns a dict with ``mask`` (both directions strictly above the horizon),
    ``nl``/``nv`` (cosines clamped to ``[_EPS, 1]``), ``nh`` (``n.h`` in ``[0, 1]``),
    ``cos2_h``/``sin2_h``
    (squared cosine/sine of the half-vector angle ``theta_h``, each in ``[0, 1]``; the
    sine is computed from ``|n x h|^2`` to stay accurate near the specular peak) and
    ``hv`` (``h.v = h.l`` in ``[0, 1]``) and ``lv`` (``l.v``). Every term is bit-identical
    under ``l <-> v``.
    """
    n, l, v = _vectors(n, l, v)
    nl_raw = _dot(n, l)
    nv_raw = _dot(n, v)
    lv = _dot(l, v)
    mask = (nl_raw > 0.0) & (nv_raw > 0.0)
    nl = np.clip(nl_raw, _EPS, 1.0)
    nv = np.clip(nv_raw, _EPS, 1.0)
    # |l + v|^2 = 2 + 2 l.v for unit vectors; symmetric in l and v by construction.
    len2_lv = np.maximum(2.0 + 2.0 * lv, _EPS)
    len_lv = np.sqrt(len2_lv)
    nh = np.clip((nl_raw + nv_raw) / len_lv, 0.0, 1.0)
    sin2_h = np.clip(_cross_norm2(n, l, v) / len2_lv, 0.0, 1.0)
    hv = np.clip(0.5 * len_lv, 0.0, 1.0)
    return {
        "mask": mask,
        "nl": nl,
        "nv": nv,
        "nh": nh,
        "cos2_h": nh * nh,
        "sin2_h": sin2_h,
        "hv": hv,
        "lv": lv,
    }


def _finish(mask: np.ndarray, value: np.ndarray) -> np.ndarray:
    shape = np.broadcast_shapes(np.shape(mask), np.shape(value))
    out = np.where(mask, value, 0.0)
    return np.broadcast_to(out, shape).astype(np.float64, copy=True)


def _param(x, name: str, *, minimum: float | None = None) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if np.any(~np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    if np.any(arr < 0.0):
        raise ValueError(f"{name} must be non-negative")
    if minimum is not None:
        arr = np.maximum(arr, minimum)
    return arr


# --------------------------------------------------------------------------- models
def lambertian(n, l, v, albedo=1.0) -> np.ndarray:
    r"""Lambertian (ideal diffuse) BRDF.

    .. math:: f(\mathbf l, \mathbf v) = \frac{\rho}{\pi}
        \quad\text{for } \mathbf n\cdot\mathbf l > 0,\ \mathbf n\cdot\mathbf v > 0,

    and 0 otherwise. The directional albedo equals ``albedo`` for every incidence.

    Parameters
    ----------
    n, l, v : array_like, shape (..., 3)
        Unit normal, unit direction to the light and unit direction to the viewer.
    albedo : float or array_like, shape (...,)
        Diffuse reflectance ``rho`` in ``[0, 1]`` (dimensionless).

    Returns
    -------
    numpy.ndarray, shape (...,)
        BRDF value in ``1/sr``.

    References
    ----------
    J. H. Lambert, *Photometria*, 1760.
    """
    n, l, v = _vectors(n, l, v)
    mask = (_dot(n, l) > 0.0) & (_dot(n, v) > 0.0)  # _geometry's mask, nothing else
    rho = _param(albedo, "albedo")
    return _finish(mask, rho / np.pi)


def blinn_phong(n, l, v, shininess, ks=1.0, *, exact: bool = False) -> np.ndarray:
    r"""Energy-normalised Blinn-Phong specular BRDF.

    .. math:: f(\mathbf l, \mathbf v) = k_s\,\frac{s + 8}{8\pi}\,
        (\mathbf n\cdot\mathbf h)^s,
        \qquad \mathbf h = \frac{\mathbf l + \mathbf v}{\lVert\mathbf l + \mathbf v\rVert},

    for ``n.l > 0`` and ``n.v > 0``, 0 otherwise. The factor ``(s + 8) / (8 pi)`` is
    the usual approximate energy normalisation of the Blinn-Phong lobe (Akenine-Moeller,
    Haines & Hoffman, *Real-Time Rendering*, 3rd ed., 2008, Sec. 7.6; see
    F. Giesen, "Derivation of Phong and Blinn-Phong BRDF normalization factors", 2009).

    It is an approximation: with ``ks = 1`` the directional albedo at normal incidence
    (where it is largest) is ``(s + 8)(2**(-s/2) + s) / ((s + 2)(s + 4))``, i.e. exactly 1
    at ``s = 0`` and as ``s -> inf`` but up to ~7.5 % above 1 near ``s ~ 9`` (the lobe is
    then slightly *not* energy conserving). With ``exact=True`` the factor is replaced by
    Giesen's exact normalisation ``(s + 2)(s + 4) / (8 pi (2**(-s/2) + s))``, which makes
    the normal-incidence albedo exactly ``ks`` (oblique incidences give less).
    Both factors depend only on ``s``, so reciprocity is unaffected.

    Parameters
    ----------
    n, l, v : array_like, shape (..., 3)
        Unit normal, unit direction to the light and unit direction to the viewer.
    shininess : float or array_like, shape (...,)
        Blinn exponent ``s >= 0`` (dimensionless).
    ks : float or array_like, shape (...,)
        Specular weight (dimensionless).
    exact : bool, optional
        Use the exact normal-incidence normalisation instead of ``(s + 8) / (8 pi)``.

    Returns
    -------
    numpy.ndarray, shape (...,)
        BRDF value in ``1/sr``.

    References
    ----------
    J. F. Blinn, "Models of light reflection for computer synthesized pictures",
    SIGGRAPH 1977.
    """
    g = _geometry(n, l, v)
    s = _param(shininess, "shininess")
    k = _param(ks, "ks")
    if exact:
        norm = (s + 2.0) * (s + 4.0) / (8.0 * np.pi * (2.0 ** (-0.5 * s) + s))
    else:
        norm = (s + 8.0) / (8.0 * np.pi)
    value = k * norm * g["nh"] ** s
    return _finish(g["mask"], value)


def _ggx_d(cos2_h, sin2_h, a2) -> np.ndarray:
    """GGX distribution ``a2 / (pi (a2 cos^2 + sin^2)^2)`` (``= D(h)`` of Walter et al. 2007).

    Written with ``a2 cos^2 + sin^2`` rather than ``cos^2 (a2 - 1) + 1`` to avoid the
    cancellation at the peak for small ``alpha``.
    """
    denom = np.maximum(a2 * cos2_h + sin2_h, a2 * 1e-3)
    return a2 / (np.pi * denom * denom)


def cook_torrance_ggx(n, l, v, roughness, f0) -> np.ndarray:
    r"""Cook-Torrance microfacet BRDF with the GGX distribution.

    .. math:: f(\mathbf l, \mathbf v) =
        \frac{D(\mathbf h)\,F(\mathbf h\cdot\mathbf v)\,G_2(\mathbf l, \mathbf v)}
             {4\,(\mathbf n\cdot\mathbf l)(\mathbf n\cdot\mathbf v)}

    with

    * ``D``: GGX distribution, ``alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2)``;
    * ``F``: Schlick's Fresnel approximation, ``f0 + (1 - f0) (1 - h.v)^5``
      (``h.v == h.l``, so it is symmetric);
    * ``G_2``: height-correlated Smith masking-shadowing for GGX,
      ``1 / (1 + Lambda(l) + Lambda(v))`` with
      ``Lambda(x) = (sqrt(1 + alpha^2 tan^2 theta_x) - 1) / 2`` (Heitz 2014),
      symmetric in ``l`` and ``v``.

    ``G_2 / (4 (n.l)(n.v))`` is evaluated in the algebraically equivalent, stable form
    ``0.5 / (n.v sqrt(alpha^2 + (1 - alpha^2)(n.l)^2)
    + n.l sqrt(alpha^2 + (1 - alpha^2)(n.v)^2))``.

    **Roughness convention:** the perceptual ``roughness`` ``r`` in ``[0, 1]`` is mapped
    to the GGX width ``alpha = r**2`` (Burley 2012 / Karis 2013); ``alpha`` is clamped
    below at ``1e-4`` so that ``roughness = 0`` stays finite. At ``l = v = n``:
    ``f = D(0) F(0) G_2 / 4 = f0 / (4 pi alpha^2)`` (``G_2 = 1``).

    Parameters
    ----------
    n, l, v : array_like, shape (..., 3)
        Unit normal, unit direction to the light and unit direction to the viewer.
    roughness : float or array_like, shape (...,)
        Perceptual roughness ``r >= 0``; ``alpha = r**2``.
    f0 : float or array_like, shape (...,)
        Fresnel reflectance at normal incidence, in ``[0, 1]``.

    Returns
    -------
    numpy.ndarray, shape (...,)
        BRDF value in ``1/sr``.

    References
    ----------
    R. L. Cook, K. E. Torrance, "A reflectance model for computer graphics",
    ACM TOG 1(1), 1982.
    B. Walter, S. R. Marschner, H. Li, K. E. Torrance, "Microfacet models for
    refraction through rough surfaces", EGSR 2007 (GGX).
    C. Schlick, "An inexpensive BRDF model for physically-based rendering", 1994.
    E. Heitz, "Understanding the masking-shadowing function in microfacet-based
    BRDFs", JCGT 3(2), 2014.
    """
    g = _geometry(n, l, v)
    r = _param(roughness, "roughness")
    fr0 = _param(f0, "f0")
    alpha = np.maximum(r * r, _ALPHA_MIN)
    a2 = alpha * alpha
    nl, nv = g["nl"], g["nv"]
    d = _ggx_d(g["cos2_h"], g["sin2_h"], a2)
    f = fr0 + (1.0 - fr0) * (1.0 - g["hv"]) ** 5
    lam_l = nv * np.sqrt(a2 + (1.0 - a2) * nl * nl)
    lam_v = nl * np.sqrt(a2 + (1.0 - a2) * nv * nv)
    vis = 0.5 / np.maximum(lam_l + lam_v, _EPS)  # = G_2 / (4 n.l n.v)
    return _finish(g["mask"], d * f * vis)


def ward(n, l, v, alpha, rho_s=1.0) -> np.ndarray:
    r"""Isotropic Ward (elliptical Gaussian) specular BRDF.

    .. math:: f(\mathbf l, \mathbf v) = \rho_s\,
        \frac{\exp\!\big(-\tan^2\theta_h / \alpha^2\big)}
             {4\pi\alpha^2\sqrt{\cos\theta_i\cos\theta_o}}

    with ``cos theta_i = n.l``, ``cos theta_o = n.v`` and ``theta_h`` the angle between
    ``n`` and the half vector; 0 where ``n.l <= 0`` or ``n.v <= 0``. The product
    ``cos theta_i cos theta_o`` is clamped at ``1e-12`` before the square root.
    Note that the original Ward model is only approximately energy conserving
    (it can exceed unit albedo at grazing angles for large ``alpha``).

    Parameters
    ----------
    n, l, v : array_like, shape (..., 3)
        Unit normal, unit direction to the light and unit direction to the viewer.
    alpha : float or array_like, shape (...,)
        RMS surface slope ``alpha > 0`` (clamped to ``1e-4``).
    rho_s : float or array_like, shape (...,)
        Specular reflectance (dimensionless).

    Returns
    -------
    numpy.ndarray, shape (...,)
        BRDF value in ``1/sr``.

    References
    ----------
    G. J. Ward, "Measuring and modeling anisotropic reflection", SIGGRAPH 1992.
    """
    g = _geometry(n, l, v)
    a = _param(alpha, "alpha", minimum=_ALPHA_MIN)
    rho = _param(rho_s, "rho_s")
    a2 = a * a
    tan2 = g["sin2_h"] / np.maximum(g["cos2_h"], _EPS)
    cos_prod = np.maximum(g["nl"] * g["nv"], _EPS)
    value = rho * np.exp(-tan2 / a2) / (4.0 * np.pi * a2 * np.sqrt(cos_prod))
    return _finish(g["mask"], value)


def ggx_bands(n, l, v, roughness, f0_rgb) -> np.ndarray:
    r"""GGX microfacet BRDF with one Schlick Fresnel term per light band (metals).

    The same model as :func:`cook_torrance_ggx`, but ``f0_rgb`` (``(3,)`` or
    ``(..., 3)``) gives the normal-incidence reflectance in the red, green and
    blue bands, so the specular colour of a metal comes from its Fresnel term:
    ``f_b = D(h) F_b(h.v) G_2 / (4 n.l n.v)``. With equal ``f0`` in every band each
    band is bit-identical to :func:`cook_torrance_ggx`.

    Parameters
    ----------
    n, l, v : array_like, shape (..., 3)
        Unit normal, unit direction to the light and unit direction to the viewer.
    roughness : float or array_like, shape (...,)
        Perceptual roughness ``r >= 0``; ``alpha = r**2``.
    f0_rgb : array_like, shape (3,) or (..., 3)
        Fresnel reflectance at normal incidence per band, in ``[0, 1]``.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        BRDF values in ``1/sr`` per band.
    """
    g = _geometry(n, l, v)
    r = _param(roughness, "roughness")
    fr0 = _param(f0_rgb, "f0_rgb")
    if fr0.ndim == 0 or fr0.shape[-1] != 3:
        raise ValueError(f"f0_rgb must have shape (..., 3), got {fr0.shape}")
    alpha = np.maximum(r * r, _ALPHA_MIN)
    a2 = alpha * alpha
    nl, nv = g["nl"], g["nv"]
    d = _ggx_d(g["cos2_h"], g["sin2_h"], a2)
    f = fr0 + (1.0 - fr0) * ((1.0 - g["hv"]) ** 5)[..., None]
    lam_l = nv * np.sqrt(a2 + (1.0 - a2) * nl * nl)
    lam_v = nl * np.sqrt(a2 + (1.0 - a2) * nv * nv)
    vis = 0.5 / np.maximum(lam_l + lam_v, _EPS)
    return _finish(g["mask"][..., None], np.asarray(d)[..., None] * f * np.asarray(vis)[..., None])


def oren_nayar(n, l, v, sigma, albedo=1.0) -> np.ndarray:
    r"""Oren-Nayar rough diffuse BRDF (the qualitative model).

    .. math:: f(\mathbf l, \mathbf v) = \frac{\rho}{\pi}\Big(A + B\,
        \frac{\max(0,\ \mathbf l\cdot\mathbf v - (\mathbf n\cdot\mathbf l)
        (\mathbf n\cdot\mathbf v))}{\max(\mathbf n\cdot\mathbf l,\ \mathbf n\cdot\mathbf v)}\Big),
        \quad A = 1 - \frac{\sigma^2}{2(\sigma^2 + 0.33)},
        \ B = \frac{0.45\,\sigma^2}{\sigma^2 + 0.09}

    which is ``rho/pi (A + B max(0, cos(phi_i - phi_o)) sin(alpha) tan(beta))``
    with ``alpha = max(theta_i, theta_o)`` and ``beta = min(theta_i, theta_o)``,
    written with the symmetric terms ``l.v - (n.l)(n.v)`` and ``max(n.l, n.v)``
    (so it is reciprocal to the bit). ``sigma = 0`` is Lambertian.

    Parameters
    ----------
    n, l, v : array_like, shape (..., 3)
        Unit normal, unit direction to the light and unit direction to the viewer.
    sigma : float or array_like, shape (...,)
        Standard deviation of the microfacet slope angle, radians.
    albedo : float or array_like, shape (...,)
        Diffuse reflectance ``rho``.

    Returns
    -------
    numpy.ndarray, shape (...,)
        BRDF value in ``1/sr``.

    References
    ----------
    M. Oren, S. K. Nayar, "Generalization of Lambert's reflectance model",
    SIGGRAPH 1994.
    """
    g = _geometry(n, l, v)
    s = _param(sigma, "sigma")
    rho = _param(albedo, "albedo")
    s2 = s * s
    a = 1.0 - 0.5 * s2 / (s2 + 0.33)
    b = 0.45 * s2 / (s2 + 0.09)
    nl, nv = g["nl"], g["nv"]
    side = np.maximum(g["lv"] - nl * nv, 0.0) / np.maximum(nl, nv)
    return _finish(g["mask"], rho / np.pi * (a + b * side))
