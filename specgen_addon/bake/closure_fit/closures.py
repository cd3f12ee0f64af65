"""Fit a spectral BRDF table with Cycles' native closures: Lambert + one or two GGX lobes per band.

The full-scene spectral render (``ops/render_fullscene.py``) lets Cycles path-trace the SpecGen
material with its own closures, so interreflection, every light type and the world work as for
any other material. Per band λ the model is

    f(ω_i, ω_o, λ) = ρ(λ)/π + Σ_l s_l(λ) · D_αl(λ)(h) G₂(ω_i, ω_o) / (4 cos θ_i cos θ_o),

Cycles' *Diffuse BSDF* (colour ρ) and *Glossy BSDF* with the plain GGX distribution (colour
``s_l``, roughness ``r_l(λ)``, ``α_l = r_l²``), where ``D`` is the GGX (Trowbridge-Reitz) normal
distribution and ``G₂`` the height-correlated Smith masking-shadowing term (Heitz 2014,
"Understanding the Masking-Shadowing Function in Microfacet-Based BRDFs", eq. 99), as in Cycles.

The albedo ``ρ(λ)`` and the specular tints ``s_l(λ)`` are per band; so, where it pays, is the
roughness ``r_l(λ)``. The fit is a linear non-negative least-squares problem once the
roughnesses are fixed (:func:`_nnls_small`, exact, all bands at once):

1. shared roughnesses, chosen on a grid (all single lobes and pairs) and refined continuously;
2. per band: from the shared values, each lobe's ``r_l(λ)`` is the shortest path through a finer
   grid (dynamic programming over the bands) of the per-band relative squared error plus
   ``SMOOTHNESS · (Δ ln r)²`` between neighbouring bands, then refined continuously band by band;
3. a lobe keeps per-band roughness only if that lowers the error summed over bands by
   ``PER_BAND_GAIN``, and a constant at its mean ``ln r`` is not as good; otherwise it keeps a
   shared value (and costs one closure per render).
   A varying lobe costs three closures, so its plain or Fresnel part is dropped when the fit
   without it is as good (error within ``PER_BAND_GAIN``, or every band within
   ``PER_BAND_MIN_ERROR``), and where two lobes vary, one varying lobe is fitted as well and
   taken instead when it is as good.
   Step 2 is skipped when the shared fit is already within ``PER_BAND_MIN_ERROR``.

A render packs three bands into one closure's R, G, B, so a lobe whose roughness varies is built
as three closures, one per channel (:func:`stack_layout`, :func:`group_closures`).

The residual is taken on ``f cos θi cos θo`` (what a table entry adds to rendered radiance per
unit light and projected area), so grazing entries, where measured and Fresnel-driven BRDFs reach
hundreds of sr⁻¹, do not swamp the fit. The error reported is the per-band relative RMS of that
residual. Figures on the corpus: docs/blender.md, ``bench/closure_fit.py``.

Angles in radians, wavelengths in nm, BRDF values in sr⁻¹.
"""

from __future__ import annotations

import itertools
import json
from dataclasses import dataclass, field

import numpy as np

from specgen_addon.bake.closure_fit.fit_check import rendered_fit_error
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import N_THETA_H, grid_angles
from specgen_addon.common.errors import SpecGenError
from specgen_addon.spectral.spectra import reflectance_to_linear_srgb

#: Roughness candidates (Blender's roughness, α = r²): near-mirror to fully rough.
ROUGHNESS_GRID = np.geomspace(0.04, 1.0, 30)
#: Candidates of the per-band search (the shared fit's values are added to them).
PER_BAND_GRID = np.geomspace(0.02, 1.0, 33)
#: Weight μ of ``Σ (ln r(λ_k+1) − ln r(λ_k))²`` against the bands' summed relative squared error.
SMOOTHNESS = 1e-3
#: Least relative drop of the summed squared error for which a lobe gets per-band roughness.
PER_BAND_GAIN = 0.05
#: Shared fits whose worst band is this close (relative RMS) are not refined per band.
PER_BAND_MIN_ERROR = 1e-3
#: Roughnesses closer than this in ``ln r`` count as equal (one closure for a band group).
SAME_ROUGHNESS = 0.01
#: Table subsampling for the fit: every θh sample (the specular peak), every 3rd θd, 6th φd.
FIT_STRIDE = (1, 3, 6)
#: Relative IOR of the Fresnel weight (dielectrics: plastics, coats, paints).
DEFAULT_IOR = 1.5
#: The three bands of a render, in a closure colour's channels.
CHANNELS = "RGB"


def ggx_lobe(wi: np.ndarray, wo: np.ndarray, roughness: float) -> np.ndarray:
    """Unit-weight GGX microfacet BRDF (sr⁻¹) of Cycles' Glossy BSDF, no Fresnel: ``D G₂ / (4 cos θi cos θo)``.

    ``wi``, ``wo`` (N, 3) unit vectors in the local frame (z = normal); zero below the horizon.
    """
    return _ggx_cosines(*_lobe_cosines(wi, wo), roughness)


def _lobe_cosines(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(cos² θh, cos θi, cos θo)`` of direction pairs, the cosines clipped to [0, 1]."""
    wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
    h = wi + wo
    ch = np.clip(h[:, 2], 0.0, None) / np.sqrt(np.maximum(np.einsum("ij,ij->i", h, h), 1e-24))
    return np.minimum(ch, 1.0) ** 2, np.clip(wi[:, 2], 0.0, 1.0), np.clip(wo[:, 2], 0.0, 1.0)


def _ggx_cosines(ch2: np.ndarray, ci: np.ndarray, co: np.ndarray, roughness: float) -> np.ndarray:
    """:func:`ggx_lobe` from :func:`_lobe_cosines` (zero where either cosine is 0)."""
    a2 = float(roughness) ** 4  # α = r², α²
    # D = α² / (π t²), t = cos² θh (α² − 1) + 1; G₂ / (4 cos θi cos θo) in the stable "visibility"
    # form of the height-correlated Smith term (Heitz 2014, eq. 99):
    # ½ / (cos θo √(α² + (1−α²) cos² θi) + cos θi √(α² + (1−α²) cos² θo)). In place: the fit
    # evaluates hundreds of roughnesses over tens of thousands of samples.
    t = ch2 * (a2 - 1.0)
    t += 1.0
    t *= t
    denom = co * np.sqrt(a2 + (1.0 - a2) * ci * ci)
    denom += ci * np.sqrt(a2 + (1.0 - a2) * co * co)
    denom *= t
    below = (ci <= 0) | (co <= 0)
    if below.any():
        denom[below] = 1.0
    out = np.divide(0.5 * a2 / np.pi, denom, out=denom)
    if below.any():
        out[below] = 0.0
    return out


def fresnel_dielectric(cos_theta: np.ndarray, ior: float) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a dielectric (relative IOR ``ior``) at ``cos θ``: the
    formula of Cycles' Fresnel node (``fresnel_dielectric_cos``), total reflection gives 1."""
    c = np.clip(np.abs(cos_theta), 0.0, 1.0)
    g2 = ior * ior - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (g - c) / (g + c)
        b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        f = 0.5 * a * a * (1.0 + b * b)
    return np.where(g2 > 0, np.nan_to_num(f, nan=1.0), 1.0)


def _varies(roughness: np.ndarray, weight: np.ndarray | None = None) -> bool:
    """Whether ``roughness`` (per band) differs by more than :data:`SAME_ROUGHNESS` in ``ln r``
    over the bands where ``weight`` (the closure's colour) is not zero."""
    r = np.asarray(roughness, np.float64)
    if weight is not None:
        r = r[np.asarray(weight) > 0]
    return bool(r.size) and float(np.ptp(np.log(r))) > SAME_ROUGHNESS


@dataclass
class ClosureFit:
    """Fitted closure stack of one spectral BRDF.

    Per band (all arrays at ``wavelengths_nm`` (Λ,)), with ``F = F_ior(cos θo)`` the dielectric
    Fresnel of the view direction (Cycles' Fresnel node):

        f = [diffuse + diffuse_fresnel (1 − F)] / π + Σ_l GGX_l(λ) · [specular_l + specular_fresnel_l F]

    ``roughness`` (L, Λ) Blender roughness of each GGX lobe per band (given as (L,), one value
    per lobe for all bands); ``specular``, ``specular_fresnel`` (L, Λ); ``rel_error`` (Λ,)
    relative RMS error per band.
    """

    wavelengths_nm: np.ndarray
    diffuse: np.ndarray
    roughness: np.ndarray
    specular: np.ndarray
    rel_error: np.ndarray
    diffuse_fresnel: np.ndarray | None = None
    specular_fresnel: np.ndarray | None = None
    ior: float = 1.5
    #: worst mean ΔE2000 of the fit against its table rendered under the check lights
    #: (:func:`specgen_addon.bake.closure_fit.fit_check.rendered_fit_error`); None when not measured
    rendered_error: float | None = None
    #: the Principled stand-in's sheen (:class:`specgen_addon.bake.closure_fit.sheen.SheenFit` as a
    #: dict), fitted beside the closures where a fibre surface needs one; None when it does not
    sheen: dict | None = None

    def __post_init__(self) -> None:
        self.wavelengths_nm = np.asarray(self.wavelengths_nm, np.float64)
        n = self.wavelengths_nm.size
        r = np.asarray(self.roughness, np.float64)
        self.roughness = np.array(np.broadcast_to(r[:, None] if r.ndim == 1 else r, (r.shape[0], n)))
        if self.diffuse_fresnel is None:
            self.diffuse_fresnel = np.zeros(n)
        if self.specular_fresnel is None:
            self.specular_fresnel = np.zeros_like(np.asarray(self.specular, np.float64).reshape(-1, n))

    @property
    def max_error(self) -> float:
        return float(np.max(self.rel_error)) if self.rel_error.size else 0.0

    @property
    def per_band_lobes(self) -> np.ndarray:
        """(L,) whether each lobe's roughness varies over the bands where it reflects."""
        return np.array([_varies(r, s + sf) for r, s, sf in
                         zip(self.roughness, self.specular, self.specular_fresnel)], bool)

    def terms(self, nonzero: bool = True) -> list[tuple[str, np.ndarray | None, bool, np.ndarray]]:
        """Closures as ``(name, roughness per band (Λ,) or None for diffuse, Fresnel-weighted,
        spectrum)``; with ``nonzero`` only those that are not zero in every band."""
        out = [("Diffuse", None, False, self.diffuse), ("Diffuse Fresnel", None, True, self.diffuse_fresnel)]
        for i, r in enumerate(self.roughness):
            out += [(f"Lobe {i + 1}", r, False, self.specular[i]),
                    (f"Lobe {i + 1} Fresnel", r, True, self.specular_fresnel[i])]
        return [t for t in out if not nonzero or np.any(np.asarray(t[3]) > 0)]

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Model BRDF (N, Λ) in sr⁻¹ at local directions ``wi`` (light), ``wo`` (view), (N, 3)."""
        wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0)).astype(float)
        f = fresnel_dielectric(wo[:, 2], self.ior)[:, None]
        out = above[:, None] * (self.diffuse[None] + self.diffuse_fresnel[None] * (1 - f)) / np.pi
        cosines = _lobe_cosines(wi, wo)
        for r, s, sf in zip(self.roughness, self.specular, self.specular_fresnel):
            tint = s[None] + sf[None] * f
            for value in np.unique(r):
                bands = r == value
                out[:, bands] += _ggx_cosines(*cosines, value)[:, None] * tint[:, bands]
        return out

    def at(self, wavelengths_nm: np.ndarray) -> ClosureFit:
        """The same fit linearly interpolated (held at the ends) to other bands."""
        w = np.asarray(wavelengths_nm, np.float64)
        interp = lambda y: np.interp(w, self.wavelengths_nm, y)
        rows = lambda m: np.stack([interp(x) for x in m]) if len(m) else np.zeros((0, w.size))
        return ClosureFit(w, interp(self.diffuse), rows(self.roughness), rows(self.specular),
                          interp(self.rel_error), interp(self.diffuse_fresnel),
                          rows(self.specular_fresnel), self.ior, self.rendered_error, self.sheen)

    def to_json(self) -> str:
        return json.dumps({"wavelengths_nm": self.wavelengths_nm.tolist(),
                           "diffuse": self.diffuse.tolist(), "roughness": self.roughness.tolist(),
                           "specular": self.specular.tolist(), "rel_error": self.rel_error.tolist(),
                           "diffuse_fresnel": self.diffuse_fresnel.tolist(),
                           "specular_fresnel": self.specular_fresnel.tolist(), "ior": self.ior,
                           "rendered_error": self.rendered_error, "sheen": self.sheen})

    @classmethod
    def from_json(cls, text: str) -> ClosureFit:
        """Read :meth:`to_json` (also the older form with one roughness per lobe)."""
        try:
            d = json.loads(text)
            wl = np.asarray(d["wavelengths_nm"], np.float64)
            spec = np.asarray(d["specular"], np.float64).reshape(-1, wl.size)
            spec_f = np.asarray(d.get("specular_fresnel", np.zeros_like(spec)), np.float64)
            rough = np.asarray(d["roughness"], np.float64)
            return cls(wl, np.asarray(d["diffuse"], np.float64),
                       rough if rough.ndim == 1 else rough.reshape(-1, wl.size), spec,
                       np.asarray(d["rel_error"], np.float64),
                       np.asarray(d.get("diffuse_fresnel", np.zeros(wl.size)), np.float64),
                       spec_f.reshape(-1, wl.size), float(d.get("ior", 1.5)),
                       None if d.get("rendered_error") is None else float(d["rendered_error"]),
                       d.get("sheen"))
        except (ValueError, KeyError, TypeError) as exc:
            raise SpecGenError(f"corrupt closure fit ({exc})") from None


# ------------------------------------------------------------------------------ the stack per render
@dataclass(frozen=True)
class StackClosure:
    """One closure of the node stack: term ``term`` of :meth:`ClosureFit.terms`, whole
    (``channel`` None) or, for a lobe with per-band roughness, only the band a render carries in
    RGB ``channel`` (0, 1, 2), with that band's roughness."""

    name: str
    term: str
    channel: int | None
    glossy: bool
    fresnel: bool


def stack_layout(fit: ClosureFit) -> list[StackClosure]:
    """The closures to build for ``fit``: one per nonzero term, three (``"Lobe 1 (R)"`` …) for a
    lobe term whose roughness varies over its bands, so a render costs more only where needed."""
    out = []
    for name, rough, fresnel, spectrum in fit.terms():
        if rough is not None and _varies(rough, spectrum):
            out += [StackClosure(f"{name} ({c})", name, j, True, fresnel) for j, c in enumerate(CHANNELS)]
        else:
            out.append(StackClosure(name, name, None, rough is not None, fresnel))
    return out


def _closure_value(c: StackClosure, colour: np.ndarray,
                   roughness: np.ndarray | None) -> tuple[np.ndarray, float | None]:
    """Colour (3,) and roughness of closure ``c`` given its term's three channel values: a split
    lobe whose three roughnesses are the same carries all channels in its R closure (the G and B
    closures get black, which Cycles skips), else channel ``c.channel`` only."""
    colour = np.asarray(colour, np.float64)
    if roughness is None:
        return colour, None
    r = np.asarray(roughness, np.float64)
    if c.channel is None or not _varies(r, colour):
        lit = colour > 0
        r0 = float(np.exp(np.mean(np.log(r[lit] if lit.any() else r))))
        return (colour if c.channel in (None, 0) else np.zeros(3)), r0
    return np.where(np.arange(3) == c.channel, colour, 0.0), float(r[c.channel])


def group_closures(fit: ClosureFit, group: np.ndarray,
                   layout: list[StackClosure]) -> dict[str, tuple[np.ndarray, float | None]]:
    """``{closure name: (colour (3,), roughness or None)}`` for one render of band group ``group``
    (three band indices into ``fit``'s bands), closures as in ``layout`` (:func:`stack_layout` of
    the fit the nodes were built from)."""
    g = np.asarray(group)
    terms = {t[0]: t for t in fit.terms(nonzero=False)}
    return {c.name: _closure_value(c, np.asarray(terms[c.term][3])[g],
                                   None if terms[c.term][1] is None else np.asarray(terms[c.term][1])[g])
            for c in layout}


def srgb_weights(wavelengths_nm: np.ndarray) -> np.ndarray | None:
    """(Λ, 3) linear-sRGB weights of a reflectance's bands under D65 (None off the visible range)."""
    wl = np.asarray(wavelengths_nm, np.float64)
    if wl.size < 3 or wl.min() > 450 or wl.max() < 650:
        return None
    try:
        return np.asarray(reflectance_to_linear_srgb(np.eye(wl.size), wl), np.float64)
    except SpecGenError:
        return None


def rgb_standin(fit: ClosureFit) -> dict[str, np.ndarray]:
    """Linear-sRGB colour (3,) of every closure of :meth:`ClosureFit.terms` (reflectances under
    D65): the RGB stand-in that F12 and the viewport show. Clipped at 0.

    Bands that do not cover the visible range give a grey of the mean value instead.
    """
    terms = fit.terms()
    if not terms:
        return {}
    spectra_ = np.stack([t[3] for t in terms])
    m = srgb_weights(fit.wavelengths_nm)
    rgb = spectra_ @ m if m is not None else np.repeat(spectra_.mean(axis=1, keepdims=True), 3, axis=1)
    rgb = np.clip(np.asarray(rgb, np.float64), 0.0, None)
    return {t[0]: rgb[i] for i, t in enumerate(terms)}


def standin_closures(fit: ClosureFit, layout: list[StackClosure]) -> dict[str, tuple[np.ndarray, float | None]]:
    """As :func:`group_closures` for the RGB stand-in (F12, viewport): :func:`rgb_standin`
    colours; a lobe's roughness per channel is its ``ln r(λ)`` averaged with that channel's
    (positive) sRGB weights times the lobe's spectrum."""
    colours = rgb_standin(fit)
    m = srgb_weights(fit.wavelengths_nm)
    terms = {t[0]: t for t in fit.terms(nonzero=False)}
    out = {}
    for c in layout:
        _, rough, _, spectrum = terms[c.term]
        if rough is None:
            out[c.name] = (colours.get(c.term, np.zeros(3)), None)
            continue
        w = (np.ones((rough.size, 3)) if m is None else np.clip(m, 0.0, None)) * np.asarray(spectrum)[:, None]
        w = np.where(w.sum(0) > 0, w, 1.0)
        per_channel = np.exp((w * np.log(rough)[:, None]).sum(0) / w.sum(0))
        out[c.name] = _closure_value(c, colours.get(c.term, np.zeros(3)), per_channel)
    return out


# ------------------------------------------------------------------------------ fitting
def _nnls_small(gram: np.ndarray, rhs: np.ndarray, tt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact NNLS on normal equations for a handful of unknowns, all bands at once.

    Minimises ``xᵀGx − 2xᵀb + tt`` over ``x ≥ 0`` for every column of ``rhs`` (K, Λ). ``gram``
    is (K, K), or (Λ, K, K) for a different design per band. Where the unconstrained optimum is
    non-negative it is the answer (the problem is convex); the other bands enumerate the active
    sets, larger faces first (the constrained optimum is the best feasible face optimum), and a
    band is done at the first feasible face optimum that meets the KKT conditions. Returns
    ``(x (K, Λ), objective (Λ,))``.
    """
    k, lam = rhs.shape
    per_band = gram.ndim == 3

    def face(idx: list[int], bands: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        g = gram[bands] if per_band else gram
        g = g[..., idx, :][..., idx]
        g = g + 1e-12 * np.trace(g, axis1=-2, axis2=-1)[..., None, None] * np.eye(len(idx))
        b = rhs[idx][:, bands]
        try:
            xs = np.linalg.solve(g, b.T[..., None])[..., 0].T if per_band else np.linalg.solve(g, b)
        except np.linalg.LinAlgError:
            return None
        return xs, tt[bands] - np.einsum("kl,kl->l", xs, b)  # at the face optimum: tt − xᵀb

    best_x = np.zeros((k, lam))
    best_obj = tt.astype(np.float64).copy()  # x = 0
    every = list(range(k))
    full = face(every, np.arange(lam)) if k else None
    done = np.zeros(lam, bool)
    if full is not None:
        done = np.all(full[0] >= 0, axis=0)
        best_x[:, done], best_obj[done] = full[0][:, done], full[1][done]
    rest = np.flatnonzero(~done)
    diag = np.diagonal(gram, axis1=-2, axis2=-1)            # (K,) or (Λ, K)
    for size in range(k - 1, 0, -1):   # large faces first: most bands hold one or two columns at 0
        for subset in itertools.combinations(every, size):
            if rest.size == 0:
                return best_x, np.maximum(best_obj, 0.0)
            idx = list(subset)
            solved = face(idx, rest)
            if solved is None:
                continue
            xs, obj = solved
            feasible = np.all(xs >= 0, axis=0)
            ok = feasible & (obj < best_obj[rest])
            if np.any(ok):
                cols = rest[ok]
                best_obj[cols] = obj[ok]
                best_x[:, cols] = 0.0
                best_x[np.ix_(idx, cols)] = xs[:, ok]
            # a feasible face optimum where the objective rises along every column held at zero
            # (KKT: (G x − b)_j ≥ 0) is the optimum of its convex problem: that band is done
            held = [j for j in every if j not in subset]
            if per_band:
                g = gram[rest]
                slope = np.einsum("bom,mb->ob", g[:, held][:, :, idx], xs) - rhs[held][:, rest]
                scale = np.sqrt(diag[rest][:, held].T * tt[rest])
            else:
                slope = gram[np.ix_(held, idx)] @ xs - rhs[held][:, rest]
                scale = np.sqrt(diag[held][:, None] * tt[rest][None])
            optimal = feasible & np.all(slope >= -1e-9 * scale, axis=0)
            rest = rest[~optimal]
    return best_x, np.maximum(best_obj, 0.0)


def _nnls_choices(gram: np.ndarray, rhs: np.ndarray, tt: np.ndarray,
                  idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_nnls_small` for many choices of columns at once: ``idx`` (C, m), or (C, Λ, m) for
    columns chosen per band, indexes the shared ``gram`` (K, K) and ``rhs`` (K, Λ). Returns
    ``(x (C, m, Λ), objective (C, Λ))``."""
    lam = rhs.shape[1]
    idx = np.broadcast_to(idx[:, None, :] if idx.ndim == 2 else idx, (idx.shape[0], lam, idx.shape[-1]))
    c, m = idx.shape[0], idx.shape[-1]
    g = gram[idx[..., :, None], idx[..., None, :]].reshape(c * lam, m, m)
    b = rhs[idx, np.arange(lam)[None, :, None]].reshape(c * lam, m).T
    x, obj = _nnls_small(g, b, np.tile(tt, c))
    return x.reshape(m, c, lam).transpose(1, 0, 2), obj.reshape(c, lam)


@dataclass
class _Samples:
    """The table entries the fit weighs, as the rows of a least-squares problem scaled by
    ``√w = cos θi cos θo``: directions, the target (N, Λ), the view direction's Fresnel weight,
    and ``tt`` (Λ,), the target's weighted energy. Lobes' columns and their products with the
    diffuse columns and the target are kept per roughness (the last 64; :meth:`lobe`), and
    without the target for the values only per-band searches try (:meth:`band_lobe`)."""

    wi: np.ndarray
    wo: np.ndarray
    weight: np.ndarray
    target: np.ndarray
    fres: np.ndarray
    tt: np.ndarray
    _lobes: dict[float, tuple[np.ndarray, ...]] = field(default_factory=dict, repr=False)
    _band_lobes: dict[float, tuple[np.ndarray, ...]] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self._cosines = _lobe_cosines(self.wi, self.wo)
        self._sqrt_w = np.sqrt(self.weight)
        #: (2, N) diffuse columns, Lambert and Lambert (1 − F), and the target (Λ, N), scaled by √w
        self.base = np.stack([np.full(len(self.weight), 1.0 / np.pi), (1.0 - self.fres) / np.pi]) * self._sqrt_w
        self.target_w = np.ascontiguousarray((self.target * self._sqrt_w[:, None]).T)
        self._known = np.concatenate([self.base, self.target_w])   # what a lobe is multiplied with
        self.base_gram, self.base_rhs = self.base @ self.base.T, self.base @ self.target_w.T

    def _columns(self, roughness: float) -> np.ndarray:
        """A lobe's columns (2, N), plain and F-weighted, scaled by √w."""
        g = _ggx_cosines(*self._cosines, roughness)
        g *= self._sqrt_w
        return np.stack([g, g * self.fres])

    def lobe(self, roughness: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One GGX lobe (plain and F-weighted): its columns (2, N) scaled by √w, their products
        with the diffuse columns (2, 2), with themselves (2, 2) and with the target (2, Λ)."""
        r = float(roughness)
        if r not in self._lobes:
            if len(self._lobes) >= 64:
                self._lobes.pop(next(iter(self._lobes)))
            cols = self._columns(r)
            # einsum, not BLAS: (2, N)·(N, 2 + Λ) is too thin to gain from (busy) BLAS threads
            known = np.einsum("in,jn->ij", cols, self._known)
            self._lobes[r] = (cols, known[:, :2], np.einsum("in,jn->ij", cols, cols), known[:, 2:])
        return self._lobes[r]

    def band_lobe(self, roughness: float, band: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`lobe` at one band: the product with the target (2,) of band ``band`` only.

        Per-band searches try a new value in every band, and the product of its columns with the
        other bands' targets would be waste: such a lobe is kept (the last 96) without it."""
        r = float(roughness)
        if r in self._lobes:
            cols, with_base, with_self, with_target = self._lobes[r]
            return cols, with_base, with_self, with_target[:, band]
        if r not in self._band_lobes:
            if len(self._band_lobes) >= 96:
                self._band_lobes.pop(next(iter(self._band_lobes)))
            cols = self._columns(r)
            self._band_lobes[r] = (cols, np.einsum("in,jn->ij", cols, self.base),
                                   np.einsum("in,jn->ij", cols, cols))
        cols, with_base, with_self = self._band_lobes[r]
        return cols, with_base, with_self, cols @ self.target_w[band]

    def normal_equations(self, roughness: list[float]) -> tuple[np.ndarray, np.ndarray]:
        """Gram (K, K) and right-hand sides (K, Λ) of the diffuse terms and these lobes."""
        if len(roughness) > 2:  # a grid of candidates: every pair's product, in one product
            phi = np.concatenate([self.base] + [self.lobe(r)[0] for r in roughness])
            return phi @ phi.T, phi @ self.target_w.T
        # one or two lobes: from the products :meth:`lobe` keeps, plus the lobes' cross product
        k = 2 + 2 * len(roughness)
        gram, rhs = np.empty((k, k)), np.empty((k, self.tt.size))
        gram[:2, :2], rhs[:2] = self.base_gram, self.base_rhs
        _fill_lobe_blocks(gram, rhs, [self.lobe(r) for r in roughness])
        return gram, rhs

    def score(self, obj: np.ndarray, bands: np.ndarray | None = None) -> np.ndarray:
        """Relative squared error per band of NNLS objectives ``obj`` (at ``bands``, default all)."""
        tt = self.tt if bands is None else self.tt[bands]
        return obj / np.maximum(tt, 1e-30)


def cell_volumes(stride_h: int = 1, stride_d: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Measure of the direction pairs each table entry stands for, as the θh (90/stride_h,) and θd
    (90/stride_d,) factors of ``dωi dωo = 4 cos θd dωh dωd``: ``∫ sin θh dθh`` and
    ``∫ sin θd cos θd dθd`` over each sample's cell (φh and φd are uniform: constant factors).

    The θh grid is quadratic (MERL: ``θh = (i/90)² · 90°``), so a third of its rows lie within
    10° of the specular peak; weighing entries alike would fit the peak and let the diffuse body,
    most of a rendered surface, go."""
    def edges(stride: int) -> np.ndarray:
        i = np.arange(0, N_THETA_H, stride, dtype=np.float64)
        return np.clip(np.concatenate([i - stride / 2, [N_THETA_H]]), 0, N_THETA_H) / N_THETA_H

    th = edges(stride_h) ** 2 * (np.pi / 2)
    td = edges(stride_d) * (np.pi / 2)
    return np.cos(th[:-1]) - np.cos(th[1:]), 0.5 * (np.sin(td[1:]) ** 2 - np.sin(td[:-1]) ** 2)


#: Residual weightings: ``"measure"`` (each entry by the direction pairs it stands for, × cos θo)
#: and ``"entries"`` (every entry alike, × cos θo; the fit's weighting before the measure one,
#: which suits some retro-reflective measured materials better, docs/blender.md).
WEIGHTINGS = ("measure", "entries")
#: Rendered error (mean CIEDE2000) below which the check keeps the first weighting's fit without
#: fitting the second: 1 ΔE2000 is about a just-noticeable colour difference, so the other
#: weighting could only lower an error no one sees (and the second fit costs as much as the first).
GOOD_ENOUGH_DELTA_E = 1.0


def _samples(table, wl: np.ndarray, resample: bool, ior: float, weighting: str = "measure") -> _Samples:
    sh, sd, sp = FIT_STRIDE
    th, td, pd = grid_angles()
    values = table.values[::sh, ::sd, ::sp]
    if resample:
        values = np.tensordot(values, table.wavelength_weights(wl), axes=([3], [0]))
    target = np.maximum(values.reshape(-1, wl.size).astype(np.float64), 0.0)
    TH, TD, PD = np.meshgrid(th[::sh], td[::sd], pd[::sp], indexing="ij")
    wi, wo = io_from_half_diff(TH.ravel(), TD.ravel(), PD.ravel())
    volume = np.multiply.outer(*cell_volumes(sh, sd))[:, :, None]        # (θh, θd, 1)
    weight = np.clip(wi[:, 2], 0, None) ** 2 * np.clip(wo[:, 2], 0, None)
    weight = weight * (np.broadcast_to(volume, TH.shape).ravel() if weighting == "measure"
                       else np.clip(wo[:, 2], 0, None))
    keep = weight > 0
    wi, wo, weight, target = wi[keep], wo[keep], weight[keep], target[keep]
    return _Samples(wi, wo, weight, target, fresnel_dielectric(wo[:, 2], ior),
                    (target * target * weight[:, None]).sum(axis=0))


def _fit_shared(s: _Samples, max_lobes: int, grid: np.ndarray) -> tuple[list[float], np.ndarray, np.ndarray]:
    """Roughnesses shared by all bands: best single lobe or pair on ``grid``, then a continuous
    coordinate search with shrinking steps. Returns ``(roughness, x (2 + 2L, Λ), obj (Λ,))``."""
    rough = np.asarray(grid, np.float64) if max_lobes else np.zeros(0)
    gram, rhs = s.normal_equations(list(rough))
    best = (float(np.sum(s.score(s.tt))), (), np.zeros((2, s.tt.size)), s.tt.copy())  # no closure
    for n in range(max_lobes + 1):  # all diffuse-only, single-lobe and (coarse) pair choices
        lobes = [()] if n == 0 else ([(j,) for j in range(len(rough))] if n == 1
                                     else list(itertools.combinations(range(0, len(rough), 2), 2)))
        if not lobes:
            continue
        idx = np.array([[0, 1] + [i for j in ls for i in (2 + 2 * j, 3 + 2 * j)] for ls in lobes])
        x, obj = _nnls_choices(gram, rhs, s.tt, idx)
        score = s.score(obj).sum(axis=1)
        i = int(np.argmin(score))
        if score[i] < best[0] - 1e-12:
            best = (float(score[i]), lobes[i], x[i], obj[i])
    _, lobes, x, obj = best
    rs = [float(rough[j]) for j in lobes]
    if not rs:
        return rs, x, obj

    def solve(values: list[float]) -> tuple[float, np.ndarray, np.ndarray]:
        xx, oo = _nnls_small(*s.normal_equations(values), s.tt)
        return float(np.sum(s.score(oo))), xx, oo

    score, x, obj = solve(rs)
    step = float(np.log(rough[1] / rough[0])) * 2 if len(rough) > 1 else 0.2
    for _ in range(7):
        step /= 2
        for i in range(len(rs)):
            for sign in (-1.0, 1.0):
                trial = list(rs)
                trial[i] = float(np.clip(rs[i] * np.exp(sign * step), 0.01, 1.0))
                t_score, t_x, t_obj = solve(trial)
                if t_score < score - 1e-15:
                    rs, score, x, obj = trial, t_score, t_x, t_obj
    return rs, x, obj


def _smoothest_path(cost: np.ndarray, log_r: np.ndarray, mu: float) -> np.ndarray:
    """Candidate index per band (Λ,) minimising ``Σ cost[k_λ, λ] + μ Σ (log_r[k_λ+1] − log_r[k_λ])²``
    (Viterbi: exact shortest path through the (K, Λ) trellis)."""
    step = mu * (log_r[:, None] - log_r[None, :]) ** 2
    acc, back = cost[:, 0].copy(), []
    for band in range(1, cost.shape[1]):
        total = acc[:, None] + step                      # previous k (rows) → next k (columns)
        back.append(np.argmin(total, axis=0))
        acc = total[back[-1], np.arange(len(log_r))] + cost[:, band]
    path = [int(np.argmin(acc))]
    for b in reversed(back):
        path.append(int(b[path[-1]]))
    return np.array(path[::-1])


def _band_equations(s: _Samples, roughness: np.ndarray,
                    bands: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-band gram (B, K, K) and right-hand sides (K, B) for lobes of per-band ``roughness``
    (L, Λ), at the band indices ``bands`` (from the products :meth:`_Samples.lobe` keeps)."""
    k = 2 + 2 * roughness.shape[0]
    gram, rhs = np.empty((len(bands), k, k)), np.empty((k, len(bands)))
    gram[:, :2, :2], rhs[:2] = s.base_gram, s.base_rhs[:, bands]
    for i, band in enumerate(bands):
        _fill_lobe_blocks(gram[i], rhs[:, i], [s.band_lobe(r, band) for r in roughness[:, band]])
    return gram, rhs


def _fill_lobe_blocks(gram: np.ndarray, rhs: np.ndarray, lobes: list[tuple[np.ndarray, ...]]) -> None:
    """Write the lobes' rows of a gram (K, K) and right-hand side (K, …) whose first two rows (the
    diffuse terms) are set: each lobe's products as :meth:`_Samples.lobe` gives them, and the
    lobes' cross products."""
    for a, (cols, with_base, with_self, with_target) in enumerate(lobes):
        ia = slice(2 + 2 * a, 4 + 2 * a)
        gram[ia, :2], gram[:2, ia], gram[ia, ia], rhs[ia] = with_base, with_base.T, with_self, with_target
        for b in range(a):
            ib = slice(2 + 2 * b, 4 + 2 * b)
            gram[ia, ib] = np.einsum("in,jn->ij", cols, lobes[b][0])
            gram[ib, ia] = gram[ia, ib].T


def _solve_bands(s: _Samples, roughness: np.ndarray, bands: np.ndarray | None = None,
                 without: tuple[int, ...] = ()) -> tuple[np.ndarray, np.ndarray]:
    """NNLS weights (2 + 2L, B) and objectives (B,) with per-band ``roughness`` (L, Λ), the
    columns ``without`` held at zero."""
    bands = np.arange(s.tt.size) if bands is None else np.asarray(bands)
    gram, rhs = _band_equations(s, roughness, bands)
    keep = [i for i in range(rhs.shape[0]) if i not in without]
    x = np.zeros_like(rhs)
    x[keep], obj = _nnls_small(gram[:, keep][:, :, keep], rhs[keep], s.tt[bands])
    return x, obj


def _moved(rough: np.ndarray, lobe: int, bands: np.ndarray, log_r: np.ndarray) -> np.ndarray:
    """``rough`` (L, Λ) with lobe ``lobe`` at ``exp(log_r)`` in ``bands`` (clipped to [0.01, 1])."""
    out = rough.copy()
    out[lobe, bands] = np.clip(np.exp(log_r), 0.01, 1.0)
    return out


def _fit_per_band(s: _Samples, shared: list[float], shared_obj: np.ndarray, mu: float,
                  grid: np.ndarray = PER_BAND_GRID) -> np.ndarray | None:
    """Per-band roughnesses (L, Λ) from the shared ones: alternating over lobes, each lobe's
    path through ``grid`` ∪ shared values (:func:`_smoothest_path`, the other lobes held), then
    parabolic steps in ``ln r`` per band, red-black (odd bands held while even ones move and vice
    versa, so every step sees fixed neighbours). None when the grid paths do not lower the
    summed error by half of :data:`PER_BAND_GAIN` (the refinement would not pay)."""
    lam, n_lobes = s.tt.size, len(shared)
    cand = np.unique(np.concatenate([np.asarray(grid, np.float64), shared]))
    log_c = np.log(cand)
    gram, rhs = s.normal_equations(list(cand))           # every candidate's columns, once
    path = np.array([[int(np.searchsorted(cand, r))] * lam for r in shared])
    bands = np.arange(lam)
    for _ in range(2):
        before = path.copy()
        for lobe in range(n_lobes):
            # every candidate k for this lobe in every band, the other lobes held: one batch
            trial = np.repeat(path[None], cand.size, axis=0)          # (K, L, Λ)
            trial[:, lobe] = np.arange(cand.size)[:, None]
            cols = np.stack([2 + 2 * trial, 3 + 2 * trial], 2).reshape(cand.size, -1, lam)
            idx = np.concatenate([np.zeros((cand.size, 1, lam), int), np.ones((cand.size, 1, lam), int),
                                  cols], 1).transpose(0, 2, 1)
            _, obj = _nnls_choices(gram, rhs, s.tt, idx)
            cost = s.score(obj)
            path[lobe] = _smoothest_path(cost, log_c, mu)
        if n_lobes == 1 or np.array_equal(path, before):
            break
    if cost[path[-1], bands].sum() > (1 - PER_BAND_GAIN / 2) * s.score(shared_obj).sum():
        return None
    rough = cand[path]

    def local(r: np.ndarray, which: np.ndarray) -> np.ndarray:
        """Per-band objective with the smoothness towards the (held) neighbours, at bands ``which``."""
        _, obj = _solve_bands(s, r, which)
        lr = np.log(r)
        pen = np.zeros(len(which))
        for nb in (which - 1, which + 1):
            ok = (nb >= 0) & (nb < lam)
            pen[ok] += mu * ((lr[:, which[ok]] - lr[:, nb[ok]]) ** 2).sum(0)
        return s.score(obj, which) + pen

    step = float(np.mean(np.diff(np.log(grid)))) / 2
    for _ in range(2):  # parabolic steps in ln r: three points, the vertex, the best of four
        for parity in (0, 1):
            which = bands[parity::2]
            current = local(rough, which)   # its neighbours may have moved
            for lobe in range(n_lobes):
                log_r = np.log(rough[lobe, which])
                moves = [np.full(len(which), -step), np.full(len(which), step)]
                f_minus, f_plus = (local(_moved(rough, lobe, which, log_r + m), which) for m in moves)
                curv = f_minus - 2 * current + f_plus
                vertex = np.where(curv > 0, step * (f_minus - f_plus) / (2 * np.where(curv > 0, curv, 1.0)), 0.0)
                moves.append(np.clip(vertex, -step, step))
                values = [f_minus, f_plus, local(_moved(rough, lobe, which, log_r + moves[2]), which)]
                for m, f in zip(moves, values):
                    better = f < current - 1e-15
                    rough[lobe, which[better]] = np.clip(np.exp(log_r[better] + m[better]), 0.01, 1.0)
                    current = np.where(better, f, current)
        step /= 4
    return rough


def _per_band_model(s: _Samples, rs: list[float], x: np.ndarray, obj: np.ndarray,
                    mu: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """From a shared fit ``(rs, x, obj)``: roughness (L, Λ), weights and objectives with each
    lobe's per-band roughness kept only where it lowers the summed error by :data:`PER_BAND_GAIN`."""
    rough = np.repeat(np.asarray(rs, np.float64)[:, None], s.tt.size, axis=1)
    if not rs or s.tt.size < 2 or np.max(s.score(obj)) <= PER_BAND_MIN_ERROR ** 2:
        return rough, x, obj
    varied = _fit_per_band(s, rs, obj, mu)
    for lobe in range(len(rs) if varied is not None else 0):
        trial = rough.copy()
        trial[lobe] = varied[lobe]
        t_x, t_obj = _solve_bands(s, trial)
        if np.sum(s.score(t_obj)) < (1 - PER_BAND_GAIN) * np.sum(s.score(obj)):
            rough, x, obj = trial, t_x, t_obj
            # the search may just have found a better shared value: its tint-weighted mean in ln r
            w = x[2 + 2 * lobe] + x[3 + 2 * lobe] + 1e-12
            trial = rough.copy()
            trial[lobe] = np.exp(np.sum(w * np.log(rough[lobe])) / np.sum(w))
            t_x, t_obj = _solve_bands(s, trial)
            if _as_good(s, t_obj, obj):
                rough, x, obj = trial, t_x, t_obj
    dropped: tuple[int, ...] = ()
    for lobe in range(len(rs)):  # a varying lobe's plain or Fresnel part costs three closures too
        for col in (3 + 2 * lobe, 2 + 2 * lobe):
            if _varies(rough[lobe]) and np.any(x[col] > 0):
                t_x, t_obj = _solve_bands(s, rough, without=dropped + (col,))
                if _as_good(s, t_obj, obj):
                    dropped, x, obj = dropped + (col,), t_x, t_obj
    return rough, x, obj


def _as_good(s: _Samples, simpler: np.ndarray, obj: np.ndarray) -> bool:
    """Whether objectives ``simpler`` are within :data:`PER_BAND_GAIN` of ``obj`` summed over the
    bands, or within :data:`PER_BAND_MIN_ERROR` in every band."""
    return bool(np.sum(s.score(simpler)) <= (1 + PER_BAND_GAIN) * np.sum(s.score(obj))
                or np.max(s.score(simpler)) <= PER_BAND_MIN_ERROR ** 2)


def fit_closures(table, wavelengths_nm: np.ndarray | None = None, max_lobes: int = 2,
                 roughness_grid: np.ndarray = ROUGHNESS_GRID, ior: float = DEFAULT_IOR,
                 per_band: bool = True, smoothness: float = SMOOTHNESS, check: bool = False,
                 weighting: str = "measure") -> ClosureFit:
    """Fit Lambert + up to ``max_lobes`` GGX lobes, each also Fresnel-weighted, to a spectral
    :class:`~specgen_addon.brdf.table.BRDFTable` (see :class:`ClosureFit` for the model).

    ``wavelengths_nm`` defaults to the table's bands (else the table is interpolated linearly in λ).
    With ``per_band`` a lobe's roughness may vary with λ (smoothness weight ``smoothness``, module
    docstring); else it is shared by all bands. ``weighting`` is one of :data:`WEIGHTINGS`. With
    ``check`` the fit's rendered colour error is measured too (:attr:`ClosureFit.rendered_error`),
    the fit is made with each weighting and the one that renders closer is kept (about twice the
    time, plus 0.2–2 s); a first fit that renders within :data:`GOOD_ENOUGH_DELTA_E` is kept
    without trying the second.
    """
    if not getattr(table, "is_spectral", False):
        raise SpecGenError("the closure fit needs a spectral BRDF table (wavelengths in nm)")
    if max_lobes not in (0, 1, 2):
        raise SpecGenError(f"max_lobes must be 0, 1 or 2, got {max_lobes}")
    if weighting not in WEIGHTINGS:
        raise SpecGenError(f"unknown weighting {weighting!r}; choose one of {', '.join(WEIGHTINGS)}")
    if check:
        fits = []
        for w in WEIGHTINGS:
            fits.append(fit_closures(table, wavelengths_nm, max_lobes, roughness_grid, ior, per_band,
                                     smoothness, weighting=w))
            fits[-1].rendered_error = rendered_fit_error(fits[-1], table)
            if fits[-1].rendered_error < GOOD_ENOUGH_DELTA_E:
                break
        return min(fits, key=lambda f: f.rendered_error)
    wl = np.asarray(table.wavelengths if wavelengths_nm is None else wavelengths_nm, np.float64)
    s = _samples(table, wl, wavelengths_nm is not None, ior, weighting)
    rs, x, obj = _fit_shared(s, max_lobes, roughness_grid)
    rough = np.repeat(np.asarray(rs, np.float64)[:, None], wl.size, axis=1)
    if per_band:
        rough, x, obj = _per_band_model(s, rs, x, obj, smoothness)
        if rough.shape[0] == 2 and any(_varies(r) for r in rough):
            # three closures a render per varying lobe: one lobe may do as well once it varies
            one = _per_band_model(s, *_fit_shared(s, 1, roughness_grid), smoothness)
            if _as_good(s, one[2], obj):
                rough, x, obj = one
    spec, spec_f = x[2::2], x[3::2]
    used = [i for i in range(rough.shape[0]) if np.any(spec[i] > 0) or np.any(spec_f[i] > 0)]
    return ClosureFit(wl, x[0], rough[used], spec[used], np.sqrt(s.score(obj)), x[1],
                      spec_f[used], float(ior))
