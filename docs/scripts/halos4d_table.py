"""The halo figures' changed / strongly changed pixels (docs/halos4d.md, "Defaults").

    PYTHONPATH=$PWD python docs/scripts/halos4d_table.py [--size 512] [--slices 256] [--only fig1bc,...]

For every figure of the gallery (`refraster.gallery.halos4d.figures`) and the three held-out
views of `tests/test_halos4d_visible.py`: the covered pixels (accumulated opacity > 0.02 in the
halos-on or the halos-off picture), the share the halos change (some channel by more than
5/255) and change strongly (more than 40/255), and the ρ and δd the picture used. Run it with
another checkout's package on PYTHONPATH to measure that checkout's defaults (the before column).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

STRONG = 40.0 / 255.0


def random_rotation(rng):
    """The held-out views' rotation (as tests/test_halos4d_visible.py draws it)."""
    q, r = np.linalg.qr(rng.standard_normal((4, 4)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def rows(quick=False):
    """(name, surface, view, halos, style, note) of the gallery figures and the held-out views."""
    import refraster.halos4d as h
    from refraster.gallery import halos4d as g
    out = [(f.name, f.surface, f.view, f.halos, f.style) for f in g.figures(quick)]
    rng = np.random.default_rng(46)
    for name, s in (("held-out spun", h.spun_trefoil()),
                    ("held-out twist", h.twist_spun_trefoil(k=2)),
                    ("held-out fermat", h.quadratic_fermat())):
        out.append((name, s, h.View4D(rotation=random_rotation(rng)), h.Halos(), h.HaloStyle()))
    return out


def measure(on, off):
    from refraster.gallery import halos4d as g
    covered = (on.alpha > g.COVER_THRESHOLD) | (off.alpha > g.COVER_THRESHOLD)
    diff = np.abs(on.image - off.image).max(axis=2)
    return (int(((diff > g.CHANGE_THRESHOLD) & covered).sum()),
            int(((diff > STRONG) & covered).sum()), int(covered.sum()))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--slices", type=int, default=256)
    ap.add_argument("--only", default=None)
    args = ap.parse_args(argv)
    from refraster.halos4d import render_halos_pair
    only = None if args.only is None else set(args.only.split(","))
    print(f"{args.size}², {args.slices} slices")
    print("| figure | covered | changed % | strongly changed % | ρ | δd | s |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, surface, view, halos, style in rows():
        if only is not None and name not in only:
            continue
        t = time.perf_counter()
        on, off = render_halos_pair(surface, view=view, width=args.size, height=args.size,
                                    slices=args.slices, halos=halos, style=style)
        ch, st, cov = measure(on, off)
        print(f"| {name} | {cov} | {100 * ch / cov:.1f} | {100 * st / cov:.1f} "
              f"| {on.stats['rho']:.3g} | {on.stats['delta_d']:.3g} "
              f"| {time.perf_counter() - t:.1f} |", flush=True)


if __name__ == "__main__":
    main()
