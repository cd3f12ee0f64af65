"""How much of the network-alone error is the representation, and how much the prediction?

For held-out materials of each corpus family, one stage of the network's forward pass, started
from its prediction for the material's canonical input, is taken as free parameters and fitted to
the material's true BRDF (μ-law MSE over random angles × wavelengths, as in training); every
weight stays frozen. ``--free``:

* ``planes``: the six planes themselves: what the plane resolution, the feature size C and the
  shared fusion + MLP can represent at best;
* ``trunk``: the plane decoder's trunk map and spectral code: what the decoder's heads can reach;
* ``latent``: the 256-d latent (and image colour) fed to the decoder: what the whole decoder can
  reach, i.e. an optimal encoder (an auto-decoder).

Both tables are then scored like ``evaluate --families`` (sphere under the protocol's distant
lights, 20 bands, spectral PSNR). The fits are *oracles* (they see the truth): a high fitted PSNR
at a stage says the stages after it are not the limit, so the gap "fitted − predicted" is what a
better prediction before that stage could gain.

Both tables are evaluated continuously (the model queried at each shading point's angles), not
through the MERL grid, so they differ from ``evaluate``'s figures by the grid's quantisation.

Usage: ``.venv/bin/python bench/plane_capacity.py [--weights W.pt] [--per-family 1] [--steps 300]
[--free planes|trunk|latent] [--tv-weight 0]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from machine import describe_machine  # bench/machine.py

REPO = Path(__file__).resolve().parents[2]


class PlanesBRDF:
    """A spectral BRDF ``eval(wi, wo, λ nm) -> f_r (N, Λ)`` from fixed planes and the model's head."""

    def __init__(self, model, planes):
        self.model, self.planes = model, planes

    def eval(self, wi: np.ndarray, wo: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
        import torch

        from specgen_addon.brdf.rusinkiewicz import half_diff_from_io
        from specgen_addon.brdf.table import mu_law_decode

        th, td, pd = (np.asarray(a, dtype=np.float32) for a in half_diff_from_io(wi, wo))
        wl = np.asarray(wavelengths_nm, dtype=np.float32)
        n, m = th.size, wl.size
        rep = lambda a: torch.from_numpy(np.repeat(a, m))[None]  # noqa: E731
        lam = torch.from_numpy(np.tile(wl, n))[None]
        with torch.no_grad():
            rp = self.model.query(self.planes, rep(th), rep(td), rep(pd), lam)[0].numpy()
        f = mu_law_decode(np.clip(rp.reshape(n, m), 0.0, None), self.model.cfg.mu)
        valid = (np.asarray(wi)[:, 2] > 0) & (np.asarray(wo)[:, 2] > 0)
        return np.where(valid[:, None], f, 0.0)


#: What the fit may change, from the most constrained to the least: the latent vector (and the
#: image colour) fed to the plane decoder, the decoder's trunk map and spectral code, or the planes.
FREE = ("latent", "trunk", "planes")


def fit_planes(model, x, mat, free: str, steps: int, seed: int, tv_weight: float = 0.0,
               pool: int = 16384, per_step: int = 4096, lr: float = 3e-3) -> tuple[dict, dict]:
    """The network's planes for the image ``x``, and planes refined from them to ``mat``'s true
    BRDF (μ-law MSE + ``tv_weight``·L_TV, as in training); only the ``free`` stage
    (:data:`FREE`) is optimised, every weight of the model stays frozen."""
    import torch

    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.brdf.table import mu_law_encode
    from specgen_addon.train.data import sample_angles

    rng = np.random.default_rng(seed)
    wl = np.linspace(380.0, 780.0, 41)
    th, td, pd = sample_angles(rng, pool)
    wi, wo = io_from_half_diff(th, td, pd)
    keep = (wi[:, 2] > 1e-6) & (wo[:, 2] > 1e-6)
    th, td, pd, wi, wo = th[keep], td[keep], pd[keep], wi[keep], wo[keep]
    fr = np.asarray(mat.eval(wi, wo, wl), dtype=np.float64)
    target = torch.from_numpy(mu_law_encode(np.maximum(np.nan_to_num(fr), 0.0), model.cfg.mu).astype(np.float32))
    angles = [torch.from_numpy(a.astype(np.float32)) for a in (th, td, pd)]
    wl_t = torch.from_numpy(wl.astype(np.float32))
    gen = model.generator
    with torch.no_grad():
        latent, colour = model.encoder(x), model.encoder.colour(x)
        start = {"latent": (latent, colour), "trunk": gen.trunk_and_code(latent, colour),
                 "planes": (model.planes(x),)}[free]
    to_planes = {"latent": gen, "trunk": gen.planes_from, "planes": lambda p: p}[free]
    with torch.no_grad():
        predicted = to_planes(*start)
    params = [({k: torch.nn.Parameter(v.clone()) for k, v in t.items()} if isinstance(t, dict)
               else torch.nn.Parameter(t.clone())) for t in start]
    leaves = [v for t in params for v in (t.values() if isinstance(t, dict) else [t])]
    opt = torch.optim.Adam(leaves, lr=lr)
    for p in model.parameters():
        p.requires_grad_(False)
    for _ in range(steps):
        i = torch.from_numpy(rng.integers(0, th.size, per_step))
        j = torch.from_numpy(rng.integers(0, wl.size, per_step))
        planes = to_planes(*params)
        pred = model.query(planes, *(a[i][None] for a in angles), wl_t[j][None])[0]
        loss = (pred - target[i, j]).pow(2).mean()
        if tv_weight:
            loss = loss + tv_weight * model.tv_loss(planes)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    with torch.no_grad():
        return predicted, {k: v.detach() for k, v in to_planes(*params).items()}


def main() -> int:
    import torch

    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.render import metrics
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM
    from specgen_addon.model.runtime.inference import network_input
    from specgen_addon.model import load_weights
    from specgen_addon.render import render_spectral, sphere_geometry
    from specgen_addon.evaluation.trained_network import mixed_test_materials

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--weights", type=Path, default=None, help="weights (.pt); default: shipped")
    ap.add_argument("--per-family", type=int, default=1, help="test materials per family (default 1)")
    ap.add_argument("--steps", type=int, default=300, help="Adam steps of the plane fit (default 300)")
    ap.add_argument("--free", choices=FREE, default="planes",
                    help="what the fit may change: the decoder's latent input, its trunk map and spectral "
                         "code, or the six planes (default)")
    ap.add_argument("--tv-weight", type=float, default=0.0,
                    help="weight of the training's plane smoothness L_TV in the fit (default 0; training: 2)")
    ap.add_argument("--resolution", type=int, default=64, help="sphere size in px (default 64)")
    args = ap.parse_args()
    if args.per_family < 1 or args.steps < 1 or args.resolution < 8:
        ap.error("--per-family and --steps must be ≥ 1, --resolution ≥ 8")
    torch.set_num_threads(1)
    print("machine:", describe_machine())
    model = load_weights(args.weights)
    geo = sphere_geometry(args.resolution)
    print(f"weights: {args.weights or 'shipped'}; {args.steps} fit steps of the {args.free}, L_TV weight {args.tv_weight:g}; distant lights, "
          f"{len(WAVELENGTHS_NM)} bands, {args.resolution}² spheres")
    print(f"{'material':10} {'family':12} {'predicted':>10} {'fitted':>8} {'gap':>6}  (dB)")
    rows = []
    t0 = time.perf_counter()
    for k, mat in enumerate(mixed_test_materials(args.per_family)):
        x = torch.from_numpy(network_input(input_image.render_input(mat), model.cfg.image_size)
                             .astype(np.float32))
        planes0, fitted = fit_planes(model, x, mat, args.free, args.steps, seed=k, tv_weight=args.tv_weight)
        gt = render_spectral(mat, geo, lights=DISTANT_LIGHTS, wavelengths_nm=WAVELENGTHS_NM).spectral
        scores = []
        for planes in (planes0, fitted):
            pred = render_spectral(PlanesBRDF(model, planes), geo, lights=DISTANT_LIGHTS,
                                   wavelengths_nm=WAVELENGTHS_NM).spectral
            scores.append(float(metrics.spectral_metrics(gt, pred, geo.mask).psnr_mean))
        fam = material_family(mat)
        rows.append((fam, *scores))
        print(f"{mat.name:10} {fam:12} {scores[0]:10.2f} {scores[1]:8.2f} {scores[1] - scores[0]:+6.2f}",
              flush=True)
    fams = sorted({r[0] for r in rows})
    print("\nby family (mean):")
    for f in fams:
        sel = np.array([r[1:] for r in rows if r[0] == f])
        print(f"  {f:12} {sel[:, 0].mean():10.2f} {sel[:, 1].mean():8.2f} {sel[:, 1].mean() - sel[:, 0].mean():+6.2f}")
    allr = np.array([r[1:] for r in rows])
    print(f"  {'all':12} {allr[:, 0].mean():10.2f} {allr[:, 1].mean():8.2f} "
          f"{allr[:, 1].mean() - allr[:, 0].mean():+6.2f}   ({len(rows)} materials, "
          f"{time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
