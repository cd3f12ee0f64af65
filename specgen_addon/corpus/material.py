"""A corpus material: isotropic spectral BRDF ``f_r(ωi, ωo, λ)`` in sr⁻¹, stored as parameters.

Layers, from the top:

* optional **clear coat**: a smooth-to-glossy dielectric GGX interface of index ``η_c`` (no
  dispersion) whose directional albedo ``E_c(μ)`` attenuates everything below by
  ``(1 − E_c(μi)) (1 − E_c(μo))``. This is reciprocal, and the albedo stays
  ``E_c(μi) + (1 − E_c(μi)) · A_base(μi) ≤ 1``;
* **specular** GGX lobe of roughness ``α`` (:mod:`.microfacet`) with Fresnel of either a
  dispersive dielectric (Cauchy ``η(λ)``) or a conductor with measured ``(η, k)(λ)``;
* **diffuse** lobe (dielectric base only) with reflectance ``ρ(λ)``, coupled to the specular
  lobe as in Kelemen & Szirmay-Kalos 2001:
  ``f_d = ρ(λ)/π · (1 − E(μi, λ)) (1 − E(μo, λ)) / (1 − Ē(λ))``, whose albedo is exactly
  ``ρ (1 − E(μi))``, so ``E(μi) + ρ (1 − E(μi)) ≤ 1`` for ``ρ ≤ 1``.

Light does not refract into the coat (no direction change, no internal absorption): a common
approximation that keeps the model analytic. Fresnel factors are looked up on a fine cosine grid
(:data:`COS_NODES`, linear; error < 1e-5 against the formulas) so a batch of angles is evaluated
for all wavelengths at once.
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass
from typing import Any, Callable

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.spectral.spectra import DEFAULT_WAVELENGTHS_NM, reflectance_to_linear_srgb, wavelength_grid
from specgen_addon.corpus.fresnel import cauchy_ior, fresnel_conductor, fresnel_dielectric
from specgen_addon.corpus.metals import METALS, metal_ior
from specgen_addon.corpus.microfacet import (cosine_weighted_mean, lookup_mu, specular_albedo_curves,
                         specular_geometry)
from specgen_addon.corpus.spectra_sources import REFLECTANCE_GRID_NM, SPLITS
from specgen_addon.brdf.table import BRDFTable

#: Cosine nodes of the Fresnel lookup (linear interpolation in cos θd).
COS_NODES = np.linspace(0.0, 1.0, 1025)
#: Wavelength grid (nm) a material is evaluated on before projecting to RGB (10 nm steps).
RGB_WAVELENGTHS_NM = wavelength_grid(380.0, 780.0, 41)
#: Roughness range accepted for any GGX lobe.
ALPHA_RANGE = (0.005, 1.0)
#: Rows evaluated per chunk (bounds the (rows, Λ) temporaries to a few MB).
CHUNK_ROWS = 1 << 16


@dataclass(frozen=True)
class Reflectance:
    """Diffuse reflectance spectrum ``ρ(λ)`` in [0, 1] on :data:`REFLECTANCE_GRID_NM`.

    ``source`` names where it came from, e.g. ``"CIE TCS/TCS03"`` or ``"Otsu2018/seed=0/7"``.
    """

    source: str
    values: tuple[float, ...]

    def __post_init__(self) -> None:
        v = np.asarray(self.values, dtype=np.float64)
        if v.shape != REFLECTANCE_GRID_NM.shape or np.any(v < 0.0) or np.any(v > 1.0):
            raise SpecGenError(f"reflectance {self.source!r} must have {REFLECTANCE_GRID_NM.size} "
                               "values in [0, 1]")

    def at(self, wavelengths_nm: np.ndarray) -> np.ndarray:
        """``ρ`` at ``wavelengths_nm`` (linear interpolation, constant outside 380–780 nm)."""
        return np.interp(np.asarray(wavelengths_nm, dtype=np.float64), REFLECTANCE_GRID_NM,
                         np.asarray(self.values))


@dataclass(frozen=True)
class Dielectric:
    """Dispersive dielectric interface: Cauchy ``η(λ) = A + B/λ²`` (λ in µm, B in µm²)."""

    cauchy_a: float
    cauchy_b_um2: float

    def ior(self, wavelengths_nm: np.ndarray) -> np.ndarray:
        return cauchy_ior(wavelengths_nm, self.cauchy_a, self.cauchy_b_um2)

    def fresnel(self, cos_theta: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
        """``F(cos θ, λ)``: shape ``cos_theta.shape + (Λ,)``."""
        eta = self.ior(wavelengths_nm)
        return fresnel_dielectric(np.asarray(cos_theta)[..., None], eta)


@dataclass(frozen=True)
class Conductor:
    """Metal interface with measured complex index (:func:`.metals.metal_ior`)."""

    metal: str

    def __post_init__(self) -> None:
        if self.metal not in METALS:
            raise SpecGenError(f"unknown metal {self.metal!r}; known: {', '.join(METALS)}")

    def fresnel(self, cos_theta: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
        eta, k = metal_ior(self.metal, wavelengths_nm)
        return fresnel_conductor(np.asarray(cos_theta)[..., None], eta, k)


@dataclass(frozen=True)
class ClearCoat:
    """Thin non-dispersive dielectric GGX layer of roughness ``alpha`` and index ``eta``."""

    alpha: float
    eta: float


@dataclass(frozen=True)
class _Lookup:
    """Per-wavelength-grid tables of one material (built once per grid, then cached)."""

    fresnel: np.ndarray  # (Λ, len(COS_NODES)) base Fresnel
    e_curves: np.ndarray | None  # (Λ, 65) specular albedo E(μ, λ) for the diffuse coupling
    diffuse_scale: np.ndarray | None  # (Λ,) ρ(λ) / (π (1 − Ē(λ)))
    coat_fresnel: np.ndarray | None  # (len(COS_NODES),)
    coat_curve: np.ndarray | None  # (1, 65)


def _lerp_nodes(table: np.ndarray, cos_d: np.ndarray) -> np.ndarray:
    """Linear lookup of ``table`` (Λ, nodes) or (nodes,) on :data:`COS_NODES` → (N, Λ) or (N,)."""
    t = np.clip(cos_d, 0.0, 1.0) * (COS_NODES.size - 1)
    i = np.minimum(t.astype(np.int64), COS_NODES.size - 2)
    f = t - i
    if table.ndim == 1:
        return table[i] * (1.0 - f) + table[i + 1] * f
    rows = np.ascontiguousarray(table.T)  # gather whole rows: far faster than columns of (Λ, nodes)
    return rows[i] * (1.0 - f)[:, None] + rows[i + 1] * f[:, None]


@dataclass(frozen=True)
class Material:
    """A corpus material. Evaluate with :meth:`eval`, :meth:`eval_hd`, :meth:`eval_rgb`.

    Parameters
    ----------
    name : unique name in its corpus.
    split : ``"train"``, ``"val"`` or ``"test"``.
    alpha : GGX roughness of the specular lobe (0.005 near-mirror … 1 matte).
    interface : :class:`Dielectric` (plastic-like, may have a diffuse lobe) or :class:`Conductor`.
    diffuse : diffuse reflectance (dielectric interface only), or None.
    coat : optional :class:`ClearCoat`.
    """

    name: str
    split: str
    alpha: float
    interface: Dielectric | Conductor
    diffuse: Reflectance | None = None
    coat: ClearCoat | None = None

    def __post_init__(self) -> None:
        if self.split not in SPLITS:
            raise SpecGenError(f"material {self.name!r}: unknown split {self.split!r}")
        for a in (self.alpha,) + ((self.coat.alpha,) if self.coat else ()):
            if not ALPHA_RANGE[0] <= a <= ALPHA_RANGE[1]:
                raise SpecGenError(f"material {self.name!r}: roughness {a} outside {ALPHA_RANGE}")
        if self.diffuse is not None and not isinstance(self.interface, Dielectric):
            raise SpecGenError(f"material {self.name!r}: a conductor has no diffuse lobe")

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters (inverse of :meth:`from_dict`)."""
        d = asdict(self)
        d["interface"] = {"kind": "conductor" if isinstance(self.interface, Conductor) else "dielectric",
                          **asdict(self.interface)}
        if self.diffuse is not None:
            d["diffuse"] = {"source": self.diffuse.source,
                            "wavelengths_nm": [float(x) for x in REFLECTANCE_GRID_NM],
                            "values": [float(x) for x in self.diffuse.values]}
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Material":
        """Rebuild a material from :meth:`to_dict` output; raises SpecGenError if malformed."""
        try:
            iface = dict(d["interface"])
            kind = iface.pop("kind")
            interface = {"conductor": Conductor, "dielectric": Dielectric}[kind](**iface)
            diffuse = None
            if d.get("diffuse") is not None:
                grid = d["diffuse"].get("wavelengths_nm")
                if grid is not None and not np.allclose(grid, REFLECTANCE_GRID_NM):
                    raise SpecGenError("diffuse spectrum is not on the 380–780 nm / 5 nm grid")
                diffuse = Reflectance(d["diffuse"]["source"], tuple(float(x) for x in d["diffuse"]["values"]))
            coat = ClearCoat(**d["coat"]) if d.get("coat") is not None else None
            return cls(str(d["name"]), str(d["split"]), float(d["alpha"]), interface, diffuse, coat)
        except (KeyError, TypeError, ValueError) as exc:
            raise SpecGenError(f"malformed material parameters ({type(exc).__name__}: {exc})") from None

    # ------------------------------------------------------------------ description
    @property
    def kind(self) -> str:
        """Short description: ``"metal:Au"``, ``"plastic"``, ``"dielectric"``, plus ``"+coat"``."""
        if isinstance(self.interface, Conductor):
            k = f"metal:{self.interface.metal}"
        else:
            k = "plastic" if self.diffuse is not None else "dielectric"
        return k + ("+coat" if self.coat is not None else "")

    # ------------------------------------------------------------------ evaluation
    def eval(self, wi: np.ndarray, wo: np.ndarray,
             wavelengths_nm: np.ndarray | None = DEFAULT_WAVELENGTHS_NM) -> np.ndarray:
        """``f_r(ωi, ωo, λ)`` in sr⁻¹, shape (N, Λ); zero if either direction is below the horizon.

        ``wi``, ``wo``: unit vectors (..., 3) in the local frame (normal +z), broadcast together
        and flattened to N rows. ``wavelengths_nm`` None means the default 21 bands.
        """
        return self._evaluate(*self._io_cosines(wi, wo), wavelengths_nm)

    def eval_hd(self, theta_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray,
                wavelengths_nm: np.ndarray = DEFAULT_WAVELENGTHS_NM) -> np.ndarray:
        """``f_r`` at Rusinkiewicz angles (radians) → (N, Λ), same as ``eval(*io_from_half_diff(...))``.

        Uses the closed forms of :func:`specgen_addon.brdf.rusinkiewicz.io_from_half_diff`:
        ``cos θi,o = cos θh cos θd ∓ sin θh sin θd cos φd``, ``ωi·h = cos θd``.
        """
        cos_i, cos_o, cos_h, cos_d = self._hd_cosines(theta_h, theta_d, phi_d)
        return self._evaluate(cos_i, cos_o, cos_h, cos_d, wavelengths_nm)

    def eval_rgb(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Linear sRGB ``f_r`` (N, 3) under D65: the spectrum on 10 nm bands, projected by the CMFs."""
        return self._evaluate(*self._io_cosines(wi, wo), RGB_WAVELENGTHS_NM, project=_rgb_projection())

    def eval_hd_rgb(self, theta_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray) -> np.ndarray:
        """Linear sRGB ``f_r`` (N, 3) at Rusinkiewicz angles (radians)."""
        cos_i, cos_o, cos_h, cos_d = self._hd_cosines(theta_h, theta_d, phi_d)
        return self._evaluate(cos_i, cos_o, cos_h, cos_d, RGB_WAVELENGTHS_NM, project=_rgb_projection())

    def tabulate(self, wavelengths_nm: np.ndarray = DEFAULT_WAVELENGTHS_NM,
                 progress: Callable[[float], None] | None = None,
                 cancel: Callable[[], bool] | None = None):
        """The material on the MERL grid as a spectral :class:`~specgen_addon.brdf.table.BRDFTable`."""
        w = np.asarray(wavelengths_nm, dtype=np.float64)
        meta = {"source": "specgen corpus", "material": self.to_dict(), "description": self.kind}
        return BRDFTable.tabulate(lambda th, td, pd: self.eval_hd(th, td, pd, w), w,
                                  metadata=meta, progress=progress, cancel=cancel)

    # ------------------------------------------------------------------ internals
    @staticmethod
    def _io_cosines(wi, wo):
        """``(cos θi, cos θo, cos θh, ωi·h)`` of direction pairs (..., 3)."""
        try:
            wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64))
        except ValueError:
            raise SpecGenError(f"wi and wo do not broadcast: {np.shape(wi)} vs {np.shape(wo)}") from None
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        h = wi + wo
        h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-12)
        return wi[:, 2], wo[:, 2], h[:, 2], np.einsum("ij,ij->i", wi, h)

    @staticmethod
    def _hd_cosines(theta_h, theta_d, phi_d):
        th = np.ravel(np.asarray(theta_h, dtype=np.float64))
        td = np.ravel(np.asarray(theta_d, dtype=np.float64))
        pd = np.ravel(np.asarray(phi_d, dtype=np.float64))
        th, td, pd = np.broadcast_arrays(th, td, pd)
        cos_h, cos_d = np.cos(th), np.cos(td)
        a = cos_h * cos_d
        b = np.sin(th) * np.sin(td) * np.cos(pd)
        return a - b, a + b, cos_h, cos_d

    def _evaluate(self, cos_i, cos_o, cos_h, cos_d, wavelengths_nm, project=None) -> np.ndarray:
        w = DEFAULT_WAVELENGTHS_NM if wavelengths_nm is None else wavelengths_nm
        w = np.atleast_1d(np.asarray(w, dtype=np.float64))
        lut = _lookup(self, tuple(float(x) for x in w))
        n = cos_i.shape[0]
        out = np.empty((n, w.size if project is None else project.shape[1]))
        for s in range(0, n, CHUNK_ROWS):
            sl = slice(s, s + CHUNK_ROWS)
            f = self._chunk(lut, cos_i[sl], cos_o[sl], cos_h[sl], cos_d[sl])
            out[sl] = f if project is None else f @ project
        return out

    def _chunk(self, lut: _Lookup, cos_i, cos_o, cos_h, cos_d) -> np.ndarray:
        valid = (cos_i > 0.0) & (cos_o > 0.0)
        geom = specular_geometry(cos_i, cos_o, cos_h, self.alpha)
        f = _lerp_nodes(lut.fresnel, cos_d)
        f *= geom[:, None]
        if lut.e_curves is not None:
            mu_i, mu_o = np.clip(cos_i, 0.0, 1.0), np.clip(cos_o, 0.0, 1.0)
            diffuse = (1.0 - lookup_mu(lut.e_curves, mu_i)) * (1.0 - lookup_mu(lut.e_curves, mu_o))
            diffuse *= lut.diffuse_scale
            f += diffuse
        if lut.coat_fresnel is not None:
            mu_i, mu_o = np.clip(cos_i, 0.0, 1.0), np.clip(cos_o, 0.0, 1.0)
            through = (1.0 - lookup_mu(lut.coat_curve, mu_i)) * (1.0 - lookup_mu(lut.coat_curve, mu_o))
            f *= through
            coat_geom = specular_geometry(cos_i, cos_o, cos_h, self.coat.alpha)
            f += (coat_geom * _lerp_nodes(lut.coat_fresnel, cos_d))[:, None]
        f[~valid] = 0.0
        return f


@functools.lru_cache(maxsize=256)
def _lookup(material: Material, wavelengths: tuple[float, ...]) -> _Lookup:
    w = np.asarray(wavelengths)
    fresnel = np.ascontiguousarray(material.interface.fresnel(COS_NODES, w).T)
    e_curves = diffuse_scale = coat_fresnel = coat_curve = None
    if material.diffuse is not None:
        e_curves = specular_albedo_curves(material.alpha, material.interface.ior(w))
        diffuse_scale = material.diffuse.at(w) / (np.pi * (1.0 - cosine_weighted_mean(e_curves)))
    if material.coat is not None:
        coat_fresnel = fresnel_dielectric(COS_NODES, material.coat.eta)
        coat_curve = specular_albedo_curves(material.coat.alpha, np.array([material.coat.eta]))
    return _Lookup(fresnel, e_curves, diffuse_scale, coat_fresnel, coat_curve)


@functools.lru_cache(maxsize=1)
def _rgb_projection() -> np.ndarray:
    """(Λ, 3) matrix taking a BRDF spectrum on :data:`RGB_WAVELENGTHS_NM` to linear sRGB under D65."""
    return reflectance_to_linear_srgb(np.eye(RGB_WAVELENGTHS_NM.size), RGB_WAVELENGTHS_NM)

