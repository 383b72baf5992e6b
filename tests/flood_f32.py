"""A float32 cutaway flood for the goldens' specificity tests ("Goldens with teeth (2)", item 6:
"float32 instead of float64 where a GPU would compute in float32").

An independent NumPy implementation of what refraster.gl's ``cutaway_flood.frag`` computes: seed
records (column, row, z, m) in float32, every pass of the schedule over the 9 candidates
``p + k·{−1, 0, 1}²``, ``C = z − m·sqrt(dy² + dx²)`` with every operation rounded to float32,
ties to the smaller row-major index; and the exact maximum with the same float32 arithmetic.
The seeds' slopes come from :func:`refraster.cutaway.surface.seed_slopes` rounded to float32 (a
shader computes them in float32 too). No floor constraint (the scenes tested have none).
"""

import numpy as np

from refraster.cutaway.flood import step_schedule
from refraster.cutaway.surface import as_angles, seed_slopes, tangent_sampling

F = np.float32


def _seeds(rear_depth, seeded, scene):
    p = scene.parameters
    cam = scene.camera
    z64 = np.where(seeded, 2.0 * np.asarray(rear_depth, np.float64) - 1.0, -np.inf)
    theta = np.full(z64.shape, float(as_angles(p["angle"])[0]))
    slope, _ = seed_slopes(z64, theta, proj=cam.proj, view=cam.view,
                           perspective_compensation=p["perspective_compensation"],
                           edge_compression=p["edge_compression"])
    # the shader: z = 2·depth − 1 in float32
    z = F(2.0) * np.asarray(rear_depth, F) - F(1.0)
    sy, sx = (F(s) for s in tangent_sampling(cam.proj, *z64.shape))
    return z, np.asarray(slope, F), sy, sx


def flood_f32(rear_depth, seeded, scene, variant):
    """D (NDC, float32) of the rear hull ``rear_depth`` (window depth) seeded where ``seeded``."""
    z, m, sy, sx = _seeds(rear_depth, seeded, scene)
    h, w = z.shape
    rows, cols = (a.astype(F) for a in np.mgrid[0:h, 0:w])
    if variant == "exact":
        return _exact_f32(z, m, seeded, rows, cols, sy, sx)
    sc = np.where(seeded, cols, F(-1))
    sr = np.where(seeded, rows, F(-1))
    sz = np.where(seeded, z, F(0))
    sm = np.where(seeded, m, F(0))
    schedule = step_schedule(h, w, variant)
    for n, k in enumerate(schedule):
        bc, br, bz, bm = (np.full((h, w), F(-1)), np.full((h, w), F(-1)),
                          np.zeros((h, w), F), np.zeros((h, w), F))
        best_c = np.zeros((h, w), F)
        best_i = np.zeros((h, w), F)
        for oy in (-1, 0, 1):
            for ox in (-1, 0, 1):
                qc, qr, qz, qm = (np.full((h, w), F(-1)), np.full((h, w), F(-1)),
                                  np.zeros((h, w), F), np.zeros((h, w), F))
                # pixel (i, j) reads (i + k·oy, j + k·ox)
                i0, i1 = max(0, -k * oy), min(h, h - k * oy)
                j0, j1 = max(0, -k * ox), min(w, w - k * ox)
                if i0 >= i1 or j0 >= j1:
                    continue
                src = (slice(i0 + k * oy, i1 + k * oy), slice(j0 + k * ox, j1 + k * ox))
                dst = (slice(i0, i1), slice(j0, j1))
                for q, s in ((qc, sc), (qr, sr), (qz, sz), (qm, sm)):
                    q[dst] = s[src]
                valid = qc >= 0
                dx = (cols - qc) * sx
                dy = (rows - qr) * sy
                d = np.sqrt(dy * dy + dx * dx)
                c = np.where(d == F(0), qz, qz - qm * d)
                idx = qr * F(w) + qc
                take = valid & ((bc < 0) | (c > best_c) | ((c == best_c) & (idx < best_i)))
                bc, br, bz, bm = (np.where(take, a, b) for a, b in
                                  ((qc, bc), (qr, br), (qz, bz), (qm, bm)))
                best_c = np.where(take, c, best_c)
                best_i = np.where(take, idx, best_i)
        sc, sr, sz, sm = bc, br, bz, bm
    return np.where(sc < 0, F(-1), np.maximum(best_c, F(-1))).astype(F)


def _exact_f32(z, m, seeded, rows, cols, sy, sx):
    out = np.full(z.shape, -np.inf, F)
    for r, c in np.argwhere(seeded):
        dx = (cols - F(c)) * sx
        dy = (rows - F(r)) * sy
        d = np.sqrt(dy * dy + dx * dx)
        v = np.where(d == F(0), z[r, c], z[r, c] - m[r, c] * d)
        np.maximum(out, v, out=out)
    return np.maximum(out, F(-1)).astype(F)
