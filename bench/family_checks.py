"""The two family checks, truth against the prediction: the network alone, the network
refined to its input photo (:func:`specgen_addon.generate.refine.refine_brdf`, the product's default) and,
for the thin films, the thin-film family's fit to the photo (``infer --model thin-film``,
:func:`specgen_addon.generate.thin_film.fit_thin_film`):

* thin film: hue (CIELAB h°, D65) of the specular direction (θh = 0) over θd for two held-out
  thin-film test materials, drawn as a figure;
* coloured highlight: for held-out tinted-coat test materials, the chromaticity of the specular
  peak (θh = 0, θd = 10°; luminance normalised to Y = 0.5 so only chromaticity counts) as ΔE2000
  between truth and prediction, and beside it at θh = 0.5°, 1° and 2° (θh = 0 itself lies inside
  one pixel of a 128² photo).

Each prediction comes from the material's sphere under the canonical lighting, by default rendered
with other environment samples than the refinement's operator
(:func:`specgen_addon.photo.sphere_image.render_independent_input`), as a real photo shares none;
``--input-photo canonical`` gives it the canonical input render itself
(:func:`specgen_addon.photo.sphere_image.render_input`, the best case for the refinement and the fit:
an inverse crime).

Usage: ``.venv/bin/python bench/family_checks.py [--weights W.pt] [--figure docs/img/thin_film_hue.png]``
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from machine import describe_machine  # bench/machine.py

REPO = Path(__file__).resolve().parents[1]

WL = np.linspace(380.0, 780.0, 41)
THETA_D = np.radians(np.linspace(0.0, 80.0, 33))
#: half angles (degrees) at which the tinted coats' peak chromaticity is also reported
PEAK_THETA_H_DEG = (0.5, 1.0, 2.0)


def _lab(spectra_rows: np.ndarray, normalise_y: float | None = None, wavelengths: np.ndarray = WL) -> np.ndarray:
    import colour

    from specgen_addon.spectral.spectra import reflectance_to_linear_srgb

    rgb = reflectance_to_linear_srgb(spectra_rows, wavelengths)
    xyz = colour.RGB_to_XYZ(rgb, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_decoding=False)
    if normalise_y is not None:
        xyz = xyz * (normalise_y / np.maximum(xyz[..., 1:2], 1e-12))
    return colour.XYZ_to_Lab(xyz, colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"])


def _specular(brdf, theta_d: np.ndarray, wavelengths: np.ndarray = WL,
              theta_h: np.ndarray | None = None) -> np.ndarray:
    """Spectra (N, Λ) of ``brdf`` at half angle ``theta_h`` (default 0: the specular direction) and
    difference angles ``theta_d`` (radians), φd = 0."""
    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff

    th = np.zeros_like(theta_d) if theta_h is None else np.asarray(theta_h, dtype=np.float64)
    wi, wo = io_from_half_diff(th, theta_d, np.zeros_like(theta_d))
    return np.asarray(brdf.eval(wi, wo, wavelengths))


def _hue_error(hue_true_deg: np.ndarray, hue_pred_deg: np.ndarray) -> np.ndarray:
    """|hue error| in degrees, the shorter way round the circle (hue is circular)."""
    return np.abs((hue_pred_deg - hue_true_deg + 180.0) % 360.0 - 180.0)


def main() -> None:
    import colour

    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.evaluation.trained_network import mixed_test_materials

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--weights", type=Path, default=None)
    p.add_argument("--figure", type=Path, default=None)
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--input-photo", choices=("independent", "canonical"), default="independent",
                   help="the photo every method sees: rendered with other samples than the refinement's "
                        "operator (default), or the canonical input render itself (an inverse crime)")
    p.add_argument("--films", type=int, default=2, help="held-out thin-film test materials (default 2; 0: none)")
    p.add_argument("--coats", type=int, default=3, help="held-out tinted-coat test materials (default 3; 0: none)")
    args = p.parse_args()
    if not (0 <= args.films <= 200 and 0 <= args.coats <= 200) or args.films + args.coats == 0:
        p.error("--films and --coats must be in 0..200, not both 0")
    if args.figure and args.films == 0:
        p.error("--figure draws the thin films: give --films ≥ 1")
    print(f"machine: {describe_machine()}")
    print(f"weights: {args.weights or 'shipped'}; input photo: {args.input_photo}")
    out: dict = {"weights": str(args.weights or "shipped"), "input_photo": args.input_photo}
    render_photo = (input_image.render_independent_input if args.input_photo == "independent"
                    else input_image.render_input)
    from specgen_addon.generate.refine import RefineOptions, refine_brdf

    from specgen_addon.generate.thin_film import fit_thin_film

    def predict(m, fit: bool = False):
        image = render_photo(m)
        table = generate_brdf(image, weights=args.weights, wavelengths_nm=WL)
        out = (table, refine_brdf(table, image, options=RefineOptions(clip_level=None)).table)
        if fit:
            film = fit_thin_film(image, clip_level=None)
            print(f"  thin-film fit of {m.name}: {film.material.kind}, η_f {film.material.film_eta:g}, "
                  f"d {film.material.thickness_nm:g} nm, α {film.material.alpha:.4g}; "
                  f"self-reproduction {film.reproduction.text()}")
            out = out + (film,)
        return out

    films = mixed_test_materials(args.films, ["thin_film"]) if args.films else []
    coats = mixed_test_materials(args.coats, ["tinted_coat"]) if args.coats else []
    curves = []
    # hue angle, unwrapped along θd (a film sweeping through red shows as a continuous curve)
    hue = lambda lab: np.degrees(np.unwrap(np.arctan2(lab[:, 2], lab[:, 1])))  # noqa: E731
    for m in films:
        tables = predict(m, fit=True)
        h_true = _lab(_specular(m, THETA_D), 0.5)
        row = {"material": m.name, "hue_true": hue(h_true).tolist()}
        hues = []
        for tag, table in zip(("network", "refined", "fit"), tables):
            h_pred = _lab(_specular(table, THETA_D), 0.5)
            de = colour.delta_E(h_true, h_pred, method="CIE 2000")
            # hue is circular: the predicted curve (unwrapped on its own) is drawn on the turn
            # nearest the truth's, and the error is the shorter way round the circle
            own = hue(h_pred)
            aligned = own + 360.0 * np.round((hue(h_true).mean() - own.mean()) / 360.0)
            error = _hue_error(hue(h_true), own)
            hues.append(aligned)
            print(f"thin film {m.name} ({m.kind}, d = {m.thickness_nm:.0f} nm, η_f = {m.film_eta}), {tag}: "
                  f"true hue span {np.ptp(hue(h_true)):.0f}°, predicted span {np.ptp(own):.0f}°, "
                  f"mean |hue error| {error.mean():.0f}°, "
                  f"mean ΔE2000 (Y-normalised) over θd {de.mean():.1f}")
            row |= {f"hue_{tag}": aligned.tolist(), f"mean_dE2000_{tag}": float(de.mean())}
        curves.append((m, hue(h_true), *hues))
        out.setdefault("thin_film", []).append(row)
    for m in coats:
        td = np.radians([10.0])
        th = np.radians(PEAK_THETA_H_DEG)
        row = {"material": m.name, "theta_h_deg": list(PEAK_THETA_H_DEG)}
        for tag, table in zip(("network", "refined"), predict(m)):
            de = float(colour.delta_E(_lab(_specular(m, td), 0.5), _lab(_specular(table, td), 0.5),
                                      method="CIE 2000")[0])
            # the peak's neighbourhood: a pixel of the 128² photo spans ≈ 0.9° of normal at the
            # centre, so θh = 0 itself is below what the photo resolves
            near = colour.delta_E(_lab(_specular(m, np.full_like(th, td[0]), theta_h=th), 0.5),
                                  _lab(_specular(table, np.full_like(th, td[0]), theta_h=th), 0.5),
                                  method="CIE 2000")
            print(f"tinted coat {m.name} ({m.kind}), {tag}: specular-peak chromaticity ΔE2000 = {de:.1f} "
                  f"({'meets' if de <= 3 else 'misses'} ≤ 3); at θh "
                  + ", ".join(f"{t:g}°: {d:.1f}" for t, d in zip(PEAK_THETA_H_DEG, near)))
            row[f"dE2000_{tag}"] = de
            row[f"dE2000_{tag}_over_theta_h"] = [float(d) for d in near]
        out.setdefault("tinted_coat", []).append(row)
    if coats:
        for tag in ("network", "refined"):
            de = np.array([r[f"dE2000_{tag}"] for r in out["tinted_coat"]])
            at1 = np.array([r[f"dE2000_{tag}_over_theta_h"][PEAK_THETA_H_DEG.index(1.0)] for r in out["tinted_coat"]])
            print(f"tinted coats, {tag}: peak ΔE2000 ≤ 3 on {int((de <= 3).sum())} of {de.size} "
                  f"(median {np.median(de):.1f}, worst {de.max():.1f}); at θh = 1°: ≤ 3 on "
                  f"{int((at1 <= 3).sum())} of {at1.size} (median {np.median(at1):.1f})")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    if args.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, len(curves), figsize=(5 * len(curves), 3.6), dpi=100)
        for ax, (m, ht, hp, hr, hf) in zip(np.atleast_1d(axes), curves):
            deg = np.degrees(THETA_D)
            ax.plot(deg, ht, "k-", lw=2.5, alpha=0.5, label="truth")
            ax.plot(deg, hp, "C3--", label="SpecGen (network alone)")
            ax.plot(deg, hr, "C0-.", label="SpecGen refined to the photo")
            ax.plot(deg, hf, "C2:", lw=2, label="thin-film fit to the photo")
            ax.set_xlabel("θd (degrees), θh = 0")
            ax.set_ylabel("CIELAB hue h° (D65, unwrapped)")
            ax.set_title(f"{m.name}: {m.kind}, d = {m.thickness_nm:.0f} nm", fontsize=9)
            ax.legend(fontsize=8)
        fig.tight_layout()
        args.figure.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.figure)
        print(f"figure: {args.figure}")


if __name__ == "__main__":
    main()
