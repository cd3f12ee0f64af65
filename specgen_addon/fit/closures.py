"""Fit a spectral BRDF table with Cycles' native closures: Lambert + one or two GGX lobes per band.

The full-scene spectral render (``ops/render_fullscene.py``) lets Cycles path-trace the SpecGen
material with its own closures, so interreflection, every light type and the world work as for
any other material. Per band λ the model is

    f(ω_i, ω_o, λ) = ρ(λ)/π + Σ_l s_l(λ) · D_αl(h) G₂(ω_i, ω_o) / (4 cos θ_i cos θ_o),

Cycles' *Diffuse BSDF* (colour ρ) and *Glossy BSDF* with the plain GGX distribution (colour
``s_l``, roughness ``r_l``, ``α_l = r_l²``), where ``D`` is the GGX (Trowbridge-Reitz) normal
distribution and ``G₂`` the height-correlated Smith masking-shadowing term (Heitz 2014,
"Understanding the Masking-Shadowing Function in Microfacet-Based BRDFs", eq. 99), as in Cycles.

A render packs three bands into one closure's R, G, B, so a lobe's roughness is shared by all
bands, while the albedo ``ρ(λ)`` and the specular tints ``s_l(λ)`` are per band. The fit is a
linear non-negative least-squares problem once the roughnesses are fixed: the roughnesses are
chosen on a grid (all single lobes and pairs), the weights solved exactly per band
(:func:`_nnls_small`). The residual is taken on ``f cos θ_i cos θ_o`` (what a table entry adds
to rendered radiance per unit light and projected area), so grazing entries, where measured and
Fresnel-driven BRDFs reach hundreds of sr⁻¹, do not swamp the fit. The error reported is the
per-band relative RMS of that residual. Measured on the corpus (rendered spheres under a sun):
metals fit at 70+ dB, plastics at 22–34 dB only (their dielectric Fresnel rise at grazing angles
and the matching darkening of the diffuse part have no Fresnel-free GGX + Lambert equivalent).

Angles in radians, wavelengths in nm, BRDF values in sr⁻¹.
"""

from __future__ import annotations

import itertools
import json
from dataclasses import dataclass

import numpy as np

from ..errors import SpecGenError
from ..rusinkiewicz import io_from_half_diff
from ..table import grid_angles

#: Roughness candidates (Blender's roughness, α = r²): near-mirror to fully rough.
ROUGHNESS_GRID = np.geomspace(0.04, 1.0, 30)
#: Table subsampling for the fit: every θh sample (the specular peak), every 3rd θd, 6th φd.
FIT_STRIDE = (1, 3, 6)
#: Relative IOR of the Fresnel weight (dielectrics: plastics, coats, paints).
DEFAULT_IOR = 1.5


def ggx_lobe(wi: np.ndarray, wo: np.ndarray, roughness: float) -> np.ndarray:
    """Unit-weight GGX microfacet BRDF (sr⁻¹) of Cycles' Glossy BSDF, no Fresnel: ``D G₂ / (4 cos θi cos θo)``.

    ``wi``, ``wo`` (N, 3) unit vectors in the local frame (z = normal); zero below the horizon.
    """
    wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
    a2 = float(roughness) ** 4  # α = r², α²
    ci, co = wi[:, 2], wo[:, 2]
    h = wi + wo
    h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-12)
    ch = np.clip(h[:, 2], 0.0, 1.0)
    d = a2 / (np.pi * (ch * ch * (a2 - 1.0) + 1.0) ** 2)

    above = (ci > 0) & (co > 0)
    # G₂ / (4 cos θi cos θo) in the stable "visibility" form of the height-correlated Smith term
    # (Heitz 2014, eq. 99): ½ / (cos θo √(α² + (1−α²) cos² θi) + cos θi √(α² + (1−α²) cos² θo)).
    cip, cop = np.clip(ci, 0.0, 1.0), np.clip(co, 0.0, 1.0)
    denom = cop * np.sqrt(a2 + (1.0 - a2) * cip ** 2) + cip * np.sqrt(a2 + (1.0 - a2) * cop ** 2)
    out = np.zeros(ci.shape)
    out[above] = d[above] * 0.5 / denom[above]
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


@dataclass
class ClosureFit:
    """Fitted closure stack of one spectral BRDF.

    Per band (all arrays at ``wavelengths_nm`` (Λ,)), with ``F = F_ior(cos θo)`` the dielectric
    Fresnel of the view direction (Cycles' Fresnel node):

        f = [diffuse + diffuse_fresnel (1 − F)] / π + Σ_l GGX_l · [specular_l + specular_fresnel_l F]

    ``roughness`` (L,) Blender roughness per GGX lobe; ``specular``, ``specular_fresnel`` (L, Λ);
    ``rel_error`` (Λ,) relative RMS error per band.
    """

    wavelengths_nm: np.ndarray
    diffuse: np.ndarray
    roughness: np.ndarray
    specular: np.ndarray
    rel_error: np.ndarray
    diffuse_fresnel: np.ndarray | None = None
    specular_fresnel: np.ndarray | None = None
    ior: float = 1.5

    def __post_init__(self) -> None:
        n = np.asarray(self.wavelengths_nm).size
        if self.diffuse_fresnel is None:
            self.diffuse_fresnel = np.zeros(n)
        if self.specular_fresnel is None:
            self.specular_fresnel = np.zeros_like(np.asarray(self.specular, np.float64).reshape(-1, n))

    @property
    def max_error(self) -> float:
        return float(np.max(self.rel_error)) if self.rel_error.size else 0.0

    def terms(self, nonzero: bool = True) -> list[tuple[str, float | None, bool, np.ndarray]]:
        """Closures as ``(name, roughness or None for diffuse, Fresnel-weighted, spectrum)``;
        with ``nonzero`` only those that are not zero in every band."""
        out = [("Diffuse", None, False, self.diffuse), ("Diffuse Fresnel", None, True, self.diffuse_fresnel)]
        for i, r in enumerate(self.roughness):
            out += [(f"Lobe {i + 1}", float(r), False, self.specular[i]),
                    (f"Lobe {i + 1} Fresnel", float(r), True, self.specular_fresnel[i])]
        return [t for t in out if not nonzero or np.any(np.asarray(t[3]) > 0)]

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Model BRDF (N, Λ) in sr⁻¹ at local directions ``wi`` (light), ``wo`` (view), (N, 3)."""
        wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0)).astype(float)
        f = fresnel_dielectric(wo[:, 2], self.ior)[:, None]
        out = above[:, None] * (self.diffuse[None] + self.diffuse_fresnel[None] * (1 - f)) / np.pi
        for r, s, sf in zip(self.roughness, self.specular, self.specular_fresnel):
            out = out + ggx_lobe(wi, wo, r)[:, None] * (s[None] + sf[None] * f)
        return out

    def at(self, wavelengths_nm: np.ndarray) -> "ClosureFit":
        """The same fit linearly interpolated (held at the ends) to other bands."""
        w = np.asarray(wavelengths_nm, np.float64)
        interp = lambda y: np.interp(w, self.wavelengths_nm, y)  # noqa: E731
        rows = lambda m: np.stack([interp(x) for x in m]) if len(m) else np.zeros((0, w.size))  # noqa: E731
        return ClosureFit(w, interp(self.diffuse), self.roughness.copy(), rows(self.specular),
                          interp(self.rel_error), interp(self.diffuse_fresnel),
                          rows(self.specular_fresnel), self.ior)

    def to_json(self) -> str:
        return json.dumps({"wavelengths_nm": self.wavelengths_nm.tolist(),
                           "diffuse": self.diffuse.tolist(), "roughness": self.roughness.tolist(),
                           "specular": self.specular.tolist(), "rel_error": self.rel_error.tolist(),
                           "diffuse_fresnel": self.diffuse_fresnel.tolist(),
                           "specular_fresnel": self.specular_fresnel.tolist(), "ior": self.ior})

    @classmethod
    def from_json(cls, text: str) -> "ClosureFit":
        try:
            d = json.loads(text)
            wl = np.asarray(d["wavelengths_nm"], np.float64)
            spec = np.asarray(d["specular"], np.float64).reshape(-1, wl.size)
            spec_f = np.asarray(d.get("specular_fresnel", np.zeros_like(spec)), np.float64)
            return cls(wl, np.asarray(d["diffuse"], np.float64),
                       np.asarray(d["roughness"], np.float64), spec,
                       np.asarray(d["rel_error"], np.float64),
                       np.asarray(d.get("diffuse_fresnel", np.zeros(wl.size)), np.float64),
                       spec_f.reshape(-1, wl.size), float(d.get("ior", 1.5)))
        except (ValueError, KeyError, TypeError) as exc:
            raise SpecGenError(f"corrupt closure fit ({exc})") from None


def _nnls_small(gram: np.ndarray, rhs: np.ndarray, tt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact NNLS on normal equations for a handful of unknowns, all bands at once.

    Minimises ``xᵀGx − 2xᵀb + tt`` over ``x ≥ 0`` for every column of ``rhs`` (K, Λ) by
    enumerating the active sets (2^K faces; the constrained optimum is the best feasible face
    optimum). Returns ``(x (K, Λ), objective (Λ,))``.
    """
    k, lam = rhs.shape
    best_x = np.zeros((k, lam))
    best_obj = tt.astype(np.float64).copy()  # x = 0
    for size in range(1, k + 1):
        for subset in itertools.combinations(range(k), size):
            idx = list(subset)
            g = gram[np.ix_(idx, idx)] + 1e-12 * np.trace(gram[np.ix_(idx, idx)]) * np.eye(size)
            try:
                xs = np.linalg.solve(g, rhs[idx])
            except np.linalg.LinAlgError:
                continue
            obj = tt - np.einsum("kl,kl->l", xs, rhs[idx])  # at the face optimum: tt − xᵀb
            ok = np.all(xs >= 0, axis=0) & (obj < best_obj)
            if np.any(ok):
                best_obj = np.where(ok, obj, best_obj)
                x = np.zeros((k, lam))
                x[idx] = xs
                best_x = np.where(ok[None], x, best_x)
    return best_x, np.maximum(best_obj, 0.0)


def fit_closures(table, wavelengths_nm: np.ndarray | None = None, max_lobes: int = 2,
                 roughness_grid: np.ndarray = ROUGHNESS_GRID, ior: float = DEFAULT_IOR) -> ClosureFit:
    """Fit Lambert + up to ``max_lobes`` GGX lobes, each also Fresnel-weighted, to a spectral
    :class:`~specgen_addon.table.BRDFTable` (see :class:`ClosureFit` for the model).

    ``wavelengths_nm`` defaults to the table's bands (else the table is interpolated linearly in λ).
    """
    if not getattr(table, "is_spectral", False):
        raise SpecGenError("the closure fit needs a spectral BRDF table (wavelengths in nm)")
    if max_lobes not in (0, 1, 2):
        raise SpecGenError(f"max_lobes must be 0, 1 or 2, got {max_lobes}")
    wl = np.asarray(table.wavelengths if wavelengths_nm is None else wavelengths_nm, np.float64)
    sh, sd, sp = FIT_STRIDE
    th, td, pd = grid_angles()
    values = table.values[::sh, ::sd, ::sp]
    if wavelengths_nm is not None:
        values = np.tensordot(values, table.wavelength_weights(wl), axes=([3], [0]))
    target = np.maximum(values.reshape(-1, wl.size).astype(np.float64), 0.0)
    TH, TD, PD = np.meshgrid(th[::sh], td[::sd], pd[::sp], indexing="ij")
    wi, wo = io_from_half_diff(TH.ravel(), TD.ravel(), PD.ravel())
    weight = (np.clip(wi[:, 2], 0, None) * np.clip(wo[:, 2], 0, None)) ** 2
    keep = weight > 0
    wi, wo, weight, target = wi[keep], wo[keep], weight[keep], target[keep]
    fres = fresnel_dielectric(wo[:, 2], ior)
    tt = (target * target * weight[:, None]).sum(axis=0)
    tt_safe = np.maximum(tt, 1e-30)
    rough = np.asarray(roughness_grid, np.float64) if max_lobes else np.zeros(0)
    # columns: Lambert, Lambert (1 − F), then per grid roughness: GGX, GGX F
    cols = [np.full(len(weight), 1.0 / np.pi), (1.0 - fres) / np.pi]
    for r in rough:
        g = ggx_lobe(wi, wo, r)
        cols += [g, g * fres]
    phi = np.stack(cols)
    gram = (phi * weight) @ phi.T
    rhs = (phi * weight) @ target
    del phi, cols
    choices: list[tuple[int, ...]] = [()]
    choices += [(j,) for j in range(len(rough))] if max_lobes >= 1 else []
    coarse = range(0, len(rough), 2)
    choices += list(itertools.combinations(coarse, 2)) if max_lobes >= 2 else []
    best = None
    for lobes in choices:
        idx = [0, 1] + [i for j in lobes for i in (2 + 2 * j, 3 + 2 * j)]
        x, obj = _nnls_small(gram[np.ix_(idx, idx)], rhs[idx], tt)
        score = float(np.sum(obj / tt_safe))
        if best is None or score < best[0] - 1e-12:
            best = (score, lobes, x, obj)
    _, lobes, x, obj = best
    rs = [float(rough[j]) for j in lobes]
    if rs:  # refine the grid's roughnesses continuously: coordinate search, shrinking steps
        base = np.stack([np.full(len(weight), 1.0 / np.pi), (1.0 - fres) / np.pi])

        def solve(values: list[float]) -> tuple[float, np.ndarray, np.ndarray]:
            p = [base]
            for r in values:
                g = ggx_lobe(wi, wo, r)
                p.append(np.stack([g, g * fres]))
            p = np.concatenate(p)
            xx, oo = _nnls_small((p * weight) @ p.T, (p * weight) @ target, tt)
            return float(np.sum(oo / tt_safe)), xx, oo

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
    spec, spec_f = x[2::2], x[3::2]
    used = [i for i in range(len(rs)) if np.any(spec[i] > 0) or np.any(spec_f[i] > 0)]
    empty = np.zeros((0, wl.size))
    return ClosureFit(wl, x[0], np.asarray(rs, np.float64)[used] if rs else np.zeros(0),
                      spec[used] if rs else empty, np.sqrt(obj / tt_safe), x[1],
                      spec_f[used] if rs else empty, float(ior))


def rgb_standin(fit: ClosureFit) -> dict[str, np.ndarray]:
    """Linear-sRGB colour (3,) of every closure of :meth:`ClosureFit.terms` (reflectances under
    D65): the RGB stand-in that F12 and the viewport show. Clipped at 0.

    Bands that do not cover the visible range give a grey of the mean value instead.
    """
    from ..spectra import reflectance_to_linear_srgb

    wl = fit.wavelengths_nm
    terms = fit.terms()
    if not terms:
        return {}
    spectra_ = np.stack([t[3] for t in terms])
    try:
        if wl.size < 3 or wl.min() > 450 or wl.max() < 650:
            raise SpecGenError("bands do not cover the visible range")
        rgb = reflectance_to_linear_srgb(spectra_, wl)
    except SpecGenError:
        rgb = np.repeat(spectra_.mean(axis=1, keepdims=True), 3, axis=1)
    rgb = np.clip(np.asarray(rgb, np.float64), 0.0, None)
    return {t[0]: rgb[i] for i, t in enumerate(terms)}
