"""What every corpus family shares: the BRDF protocol, serialisation, and albedo quadrature.

A family material is a frozen dataclass that implements one method,
``_spectral(cos_i, cos_o, cos_h, cos_d, wavelengths_nm) -> (N, Λ)`` in sr⁻¹, from the four
cosines an isotropic BRDF depends on (``cos θi``, ``cos θo``, ``cos θh`` and ``ωi·h = cos θd``);
:class:`FamilyMaterial` turns it into the project's BRDF protocol (``eval``, ``eval_hd``,
``eval_rgb``, ``tabulate``) exactly as :class:`~specgen_addon.corpus.material.Material` does.

Directional albedo ``E(μ, λ) = ∫ f_r(ωi, ωo, λ) cos θo dωo`` is integrated by
:func:`directional_albedo` on two quadratures: over GGX-warped half vectors (exact for narrow
specular lobes; Heitz 2014's change of variables, as :mod:`..microfacet` does) and over a
cosine-spaced hemisphere (broad lobes: sheen, retro-reflection). Families use it for the
energy-conserving diffuse coupling of Kelemen & Szirmay-Kalos 2001 and to keep every lobe's
albedo ≤ 1; tests use it as a white furnace.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any, Callable, ClassVar, Iterable

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.spectral.spectra import DEFAULT_WAVELENGTHS_NM, wavelength_grid
from specgen_addon.corpus.material import (ALPHA_RANGE, CHUNK_ROWS, RGB_WAVELENGTHS_NM, ClearCoat, Conductor, Dielectric,
                        Material, Reflectance, _rgb_projection)
from specgen_addon.corpus.microfacet import MU_NODES, smith_lambda
from specgen_addon.corpus.spectra_sources import REFLECTANCE_GRID_NM, SPLITS
from specgen_addon.brdf.table import BRDFTable

#: Wavelength grid (nm) on which per-material albedo curves are integrated, then interpolated.
ALBEDO_WAVELENGTHS_NM = wavelength_grid(380.0, 780.0, 41)

#: Registry of families: ``family`` name → class (filled by :func:`register`).
FAMILIES: dict[str, type["FamilyMaterial"]] = {}


def register(cls: type["FamilyMaterial"]) -> type["FamilyMaterial"]:
    FAMILIES[cls.family] = cls
    return cls


def check_alpha(name: str, *alphas: float) -> None:
    for a in alphas:
        if not ALPHA_RANGE[0] <= a <= ALPHA_RANGE[1]:
            raise SpecGenError(f"material {name!r}: roughness {a} outside {ALPHA_RANGE}")


@dataclass(frozen=True)
class FamilyMaterial:
    """Base of the corpus families: ``name``, ``split`` and the BRDF protocol (module docstring)."""

    name: str
    split: str
    family: ClassVar[str] = "base"

    def __post_init__(self) -> None:
        if self.split not in SPLITS:
            raise SpecGenError(f"material {self.name!r}: unknown split {self.split!r}")

    # ------------------------------------------------------------------ description
    @property
    def kind(self) -> str:
        return self.family

    # ------------------------------------------------------------------ evaluation
    def eval(self, wi: np.ndarray, wo: np.ndarray,
             wavelengths_nm: np.ndarray | None = DEFAULT_WAVELENGTHS_NM) -> np.ndarray:
        """``f_r(ωi, ωo, λ)`` in sr⁻¹, (N, Λ); zero if either direction is below the horizon."""
        return self._evaluate(*Material._io_cosines(wi, wo), wavelengths_nm)

    def eval_hd(self, theta_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray,
                wavelengths_nm: np.ndarray = DEFAULT_WAVELENGTHS_NM) -> np.ndarray:
        """``f_r`` at Rusinkiewicz angles (radians) → (N, Λ)."""
        return self._evaluate(*Material._hd_cosines(theta_h, theta_d, phi_d), wavelengths_nm)

    def eval_rgb(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Linear sRGB ``f_r`` (N, 3) under D65 (10 nm bands projected by the CMFs)."""
        return self._evaluate(*Material._io_cosines(wi, wo), RGB_WAVELENGTHS_NM, project=_rgb_projection())

    def eval_hd_rgb(self, theta_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray) -> np.ndarray:
        return self._evaluate(*Material._hd_cosines(theta_h, theta_d, phi_d), RGB_WAVELENGTHS_NM,
                              project=_rgb_projection())

    def tabulate(self, wavelengths_nm: np.ndarray = DEFAULT_WAVELENGTHS_NM, progress=None, cancel=None):
        """The material on the MERL grid as a spectral :class:`~specgen_addon.brdf.table.BRDFTable`."""
        w = np.asarray(wavelengths_nm, dtype=np.float64)
        meta = {"source": "specgen corpus", "material": self.to_dict(), "description": self.kind}
        return BRDFTable.tabulate(lambda th, td, pd: self.eval_hd(th, td, pd, w), w,
                                  metadata=meta, progress=progress, cancel=cancel)

    def _evaluate(self, cos_i, cos_o, cos_h, cos_d, wavelengths_nm, project=None) -> np.ndarray:
        w = DEFAULT_WAVELENGTHS_NM if wavelengths_nm is None else wavelengths_nm
        w = np.atleast_1d(np.asarray(w, dtype=np.float64))
        n = cos_i.shape[0]
        out = np.empty((n, w.size if project is None else project.shape[1]))
        for s in range(0, n, CHUNK_ROWS):
            sl = slice(s, s + CHUNK_ROWS)
            ci, co = cos_i[sl], cos_o[sl]
            valid = (ci > 0.0) & (co > 0.0)
            f = np.zeros((ci.size, w.size))
            if np.any(valid):
                f[valid] = self._spectral(ci[valid], co[valid], cos_h[sl][valid],
                                          np.clip(cos_d[sl][valid], 0.0, 1.0), w)
            out[sl] = f if project is None else f @ project
        return out

    def _spectral(self, cos_i, cos_o, cos_h, cos_d, w) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters with a ``family`` key (inverse of :func:`material_from_dict`)."""
        d: dict[str, Any] = {"family": self.family}
        for f in dataclasses.fields(self):
            d[f.name] = _encode(getattr(self, f.name))
        return d


def _encode(v: Any) -> Any:
    if isinstance(v, Reflectance):
        return {"source": v.source, "wavelengths_nm": [float(x) for x in REFLECTANCE_GRID_NM],
                "values": [float(x) for x in v.values]}
    if isinstance(v, (Conductor, Dielectric)):
        return {"kind": "conductor" if isinstance(v, Conductor) else "dielectric", **dataclasses.asdict(v)}
    if isinstance(v, ClearCoat):
        return dataclasses.asdict(v)
    if isinstance(v, Material):
        return v.to_dict()
    return v


def _decode(v: Any) -> Any:
    if isinstance(v, dict):
        if "family" in v or "interface" in v:
            return material_from_dict(v)
        if "values" in v and "source" in v:
            grid = v.get("wavelengths_nm")
            if grid is not None and not np.allclose(grid, REFLECTANCE_GRID_NM):
                raise SpecGenError("spectrum is not on the 380–780 nm / 5 nm grid")
            return Reflectance(str(v["source"]), tuple(float(x) for x in v["values"]))
        if "kind" in v:
            d = dict(v)
            return {"conductor": Conductor, "dielectric": Dielectric}[d.pop("kind")](**d)
        if set(v) == {"alpha", "eta"}:
            return ClearCoat(**v)
    return v


def family_names() -> tuple[str, ...]:
    """Every family name, the classic recipe first (the registered families in import order)."""
    return ("classic",) + tuple(FAMILIES)


def check_family_names(names: Iterable[str]) -> None:
    """SpecGenError naming every entry of ``names`` that is not a corpus family."""
    known = family_names()
    unknown = sorted(set(names) - set(known))
    if unknown:
        raise SpecGenError(f"unknown material famil{'y' if len(unknown) == 1 else 'ies'} "
                           f"{', '.join(map(repr, unknown))}; known: {', '.join(known)}")


def material_from_dict(d: dict[str, Any]):
    """A corpus material (any family; no ``family`` key means the classic :class:`Material`)."""
    if not isinstance(d, dict):
        raise SpecGenError("malformed material parameters (not an object)")
    family = d.get("family", "classic")
    if family == "classic":
        return Material.from_dict({k: v for k, v in d.items() if k != "family"})
    check_family_names([family])
    cls = FAMILIES[family]
    try:
        kwargs = {f.name: _decode(d[f.name]) for f in dataclasses.fields(cls) if f.name in d}
        return cls(**kwargs)
    except (KeyError, TypeError, ValueError) as exc:
        raise SpecGenError(f"malformed {family} material parameters ({type(exc).__name__}: {exc})") from None


# --- directional albedo by quadrature -------------------------------------------------------------

@dataclass(frozen=True)
class Quadrature:
    """Points ``(cos θi, cos θo, cos θh, ωi·h)`` with weights: ``E(μ_r) ≈ Σ_{row=r} w f cos θo``."""

    cos_i: np.ndarray
    cos_o: np.ndarray
    cos_h: np.ndarray
    cos_d: np.ndarray
    weight: np.ndarray  # includes cos θo and the Jacobian
    row: np.ndarray     # index into MU_NODES


@functools.lru_cache(maxsize=8)  # ~5 MB each; callers cache the albedo curves they make
def halfvector_quadrature(alpha: float, n_u: int = 48, n_phi: int = 32) -> Quadrature:
    """Quadrature over GGX(α)-warped half vectors: ``tan²θh = α² u/(1−u)``, φ ∈ [0, π] doubled.

    ``D cos θh dωh = du dφ / 2π`` and ``dωo = 4 (ωi·h) dωh``: weight ``4 (ωi·h) cos θo / (2π D cos θh)``.
    """
    x, wx = np.polynomial.legendre.leggauss(n_u)
    u, wu = 0.5 * (x + 1.0), 0.5 * wx
    phi = (np.arange(n_phi) + 0.5) * np.pi / n_phi
    wphi = np.full(n_phi, 2.0 * np.pi / n_phi)
    mu = np.maximum(MU_NODES, 1e-3)[:, None, None]
    tan2 = alpha ** 2 * u[None, :, None] / (1.0 - u[None, :, None])
    cos_h = 1.0 / np.sqrt(1.0 + tan2)
    sin_h = np.sqrt(tan2) * cos_h
    sin_i = np.sqrt(1.0 - mu * mu)
    i_dot_h = sin_i * sin_h * np.cos(phi[None, None, :]) + mu * cos_h
    cos_o = 2.0 * i_dot_h * cos_h - mu
    a2 = alpha * alpha
    d = a2 / (np.pi * ((a2 - 1.0) * cos_h ** 2 + 1.0) ** 2)
    w = 4.0 * i_dot_h * cos_o / (2.0 * np.pi * d * cos_h) * (wu[None, :, None] * wphi[None, None, :])
    shape = (MU_NODES.size, n_u, n_phi)
    b = lambda a: np.broadcast_to(a, shape).ravel()  # noqa: E731
    ok = b((i_dot_h > 0) & (cos_o > 0))
    row = b(np.arange(MU_NODES.size)[:, None, None])
    return Quadrature(b(mu)[ok], b(cos_o)[ok], b(cos_h)[ok], b(i_dot_h)[ok], b(w)[ok], row[ok])


@functools.lru_cache(maxsize=4)
def hemisphere_quadrature(n_mu: int = 48, n_phi: int = 48) -> Quadrature:
    """Gauss–Legendre in ``cos θo`` × midpoint in ``φ ∈ [0, π]`` (doubled): broad lobes."""
    x, wx = np.polynomial.legendre.leggauss(n_mu)
    co, wc = 0.5 * (x + 1.0), 0.5 * wx
    phi = (np.arange(n_phi) + 0.5) * np.pi / n_phi
    wphi = np.full(n_phi, 2.0 * np.pi / n_phi)
    mu = np.maximum(MU_NODES, 1e-3)[:, None, None]
    sin_i = np.sqrt(1.0 - mu * mu)
    cos_o = co[None, :, None]
    sin_o = np.sqrt(1.0 - cos_o ** 2)
    hx = sin_i + sin_o * np.cos(phi[None, None, :])
    hy = sin_o * np.sin(phi[None, None, :])
    hz = mu + cos_o
    norm = np.sqrt(hx * hx + hy * hy + hz * hz)
    cos_h = hz / norm
    i_dot_h = (sin_i * hx + mu * hz) / norm
    w = cos_o * wc[None, :, None] * wphi[None, None, :]
    shape = (MU_NODES.size, n_mu, n_phi)
    b = lambda a: np.broadcast_to(a, shape).ravel()  # noqa: E731
    row = b(np.arange(MU_NODES.size)[:, None, None])
    return Quadrature(b(mu), b(cos_o), b(cos_h), b(np.clip(i_dot_h, 0, 1)), b(w), row)


def directional_albedo(fn: Callable[..., np.ndarray], quad: Quadrature,
                       wavelengths_nm: np.ndarray = ALBEDO_WAVELENGTHS_NM) -> np.ndarray:
    """``E(μ, λ)`` at :data:`~..microfacet.MU_NODES` × ``wavelengths_nm`` of ``fn(ci, co, ch, cd, w)``."""
    w = np.asarray(wavelengths_nm, dtype=np.float64)
    out = np.zeros((MU_NODES.size, w.size))
    step = max(1, CHUNK_ROWS // 2)
    for s in range(0, quad.cos_i.size, step):
        sl = slice(s, s + step)
        f = fn(quad.cos_i[sl], quad.cos_o[sl], quad.cos_h[sl], quad.cos_d[sl], w)
        fw = f * quad.weight[sl, None]
        for j in range(w.size):
            out[:, j] += np.bincount(quad.row[sl], fw[:, j], minlength=MU_NODES.size)
    return out


def curves_at(curves: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Albedo curves (μ, ALBEDO λ) resampled to ``wavelengths_nm`` → (Λ, μ) (linear, clamped)."""
    w = np.asarray(wavelengths_nm, dtype=np.float64)
    return np.stack([np.interp(w, ALBEDO_WAVELENGTHS_NM, row) for row in curves], axis=1)


def smith_g2(cos_i: np.ndarray, cos_o: np.ndarray, alpha: float) -> np.ndarray:
    """Height-correlated Smith ``G2`` of GGX (Heitz 2014, eq. 99)."""
    return 1.0 / (1.0 + smith_lambda(cos_i, alpha) + smith_lambda(cos_o, alpha))
