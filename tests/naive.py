"""Slow, obvious reference versions of refraster's kernels, for bit-for-bit comparisons.

Written from the documented rules, not from the kernels: plain Python integers for the edge
functions, NumPy scalars for the float formulas.
"""

import numpy as np


def vertex_stage32(vertices, mvp):
    """clip = ((m0·x + m1·y) + m2·z) + m3 in float32."""
    m = mvp.astype(np.float32)
    v = vertices.astype(np.float32)
    out = np.zeros((len(v), 4), np.float32)
    for r in range(4):
        out[:, r] = ((m[r, 0] * v[:, 0] + m[r, 1] * v[:, 1]) + m[r, 2] * v[:, 2]) + m[r, 3]
    return out


def window_fixed(clip_row, width, height, bits):
    """Snapped fixed-point window position and float32 depth of one clip-space vertex."""
    x, y, z, w = (np.float32(c) for c in clip_row)
    rw = np.float32(1.0) / w
    hw, hh, half = np.float32(width / 2), np.float32(height / 2), np.float32(0.5)
    xw = x * rw * hw + hw
    yw = y * rw * hh + hh
    zw = z * rw * half + half
    s = np.float32(1 << bits)
    return (int(np.rint((xw - half) * s)), int(np.rint((yw - half) * s)), float(zw), 1.0 / float(w),
            float(xw), float(yw))


def raster_unclipped(clip, faces, width, height, bits=8, rule="bottom-left", cull="none"):
    """Fragments of faces that need no clipping: list of
    (face, row, col, depth float32, bary float32[3], front)."""
    frags = []
    one = 1 << bits
    for fi, f in enumerate(faces):
        verts = [window_fixed(clip[i], width, height, bits) for i in f]
        X = [v[0] for v in verts]
        Y = [v[1] for v in verts]
        area = (X[1] - X[0]) * (Y[2] - Y[0]) - (X[2] - X[0]) * (Y[1] - Y[0])
        if area == 0:
            continue
        front = area > 0
        if (cull == "back" and not front) or (cull == "front" and front):
            continue
        order = [0, 1, 2] if front else [0, 2, 1]
        X = [X[k] for k in order]
        Y = [Y[k] for k in order]
        Z = [verts[k][2] for k in order]
        IW = [verts[k][3] for k in order]
        FX = [verts[k][4] for k in order]
        FY = [verts[k][5] for k in order]
        farea = (FX[1] - FX[0]) * (FY[2] - FY[0]) - (FX[2] - FX[0]) * (FY[1] - FY[0])
        B = np.eye(3)[order]
        area = abs(area)
        for py in range(height):
            for px in range(width):
                cx, cy = px * one, py * one
                es = []
                inside = True
                for k in range(3):
                    a, b = (k + 1) % 3, (k + 2) % 3
                    dx, dy = X[b] - X[a], Y[b] - Y[a]
                    e = dx * (cy - Y[a]) - dy * (cx - X[a])
                    if rule == "bottom-left":
                        owns = dy < 0 or (dy == 0 and dx > 0)
                    else:
                        owns = dy < 0 or (dy == 0 and dx < 0)
                    if e < 0 or (e == 0 and not owns):
                        inside = False
                    es.append(e)
                if not inside:
                    continue
                if farea > 0:
                    # interpolation from the unsnapped positions at the pixel centre
                    cx, cy = px + 0.5, py + 0.5
                    inv = 1.0 / farea
                    lam = []
                    for k in range(3):
                        a, b = (k + 1) % 3, (k + 2) % 3
                        lam.append(((FX[b] - FX[a]) * (cy - FY[a])
                                    - (FY[b] - FY[a]) * (cx - FX[a])) * inv)
                else:
                    inv_area = 1.0 / float(area)
                    lam = [float(e) * inv_area for e in es]
                if farea > 0:
                    # the depth plane through the unsnapped vertices
                    a, b = Z[1] - Z[0], Z[2] - Z[0]
                    dzdx = (a * (FY[2] - FY[0]) - b * (FY[1] - FY[0])) * (1.0 / farea)
                    dzdy = (b * (FX[1] - FX[0]) - a * (FX[2] - FX[0])) * (1.0 / farea)
                    z = Z[0] + dzdx * ((px + 0.5) - FX[0]) + dzdy * ((py + 0.5) - FY[0])
                else:
                    z = lam[0] * Z[0] + lam[1] * Z[1] + lam[2] * Z[2]
                z = np.float32(min(max(z, 0.0), 1.0))
                q = [lk * iw for lk, iw in zip(lam, IW)]
                s = q[0] + q[1] + q[2]
                bary = np.array([(q[0] * B[0, j] + q[1] * B[1, j] + q[2] * B[2, j]) / s
                                 for j in range(3)], np.float32)
                frags.append((fi, height - 1 - py, px, z, bary, front))
    return frags


def resolve_less(frags_sorted, width, height):
    """Depth test LESS in the given order: (H, W) face index and depth."""
    depth = np.ones((height, width), np.float32)
    face = np.full((height, width), -1)
    for fi, row, col, z, _, _ in frags_sorted:
        if z < depth[row, col]:
            depth[row, col] = z
            face[row, col] = fi
    return face, depth


def jump_flood(z, slope, steps, sampling=(1.0, 1.0), floor_slope=None, floor_normal=None):
    """Jump flooding of the cutaway function as documented in refraster.cutaway.flood and
    MATH.md D-C5, pixel by pixel in Python floats (IEEE double, no fused multiply-add): per step
    k every pixel p takes, among its own seed and the seeds held by p + k·{−1, 0, 1}², the one
    with the largest C_s(p) = z(s) − m(s, p)·‖p − s‖ (ties: smaller row-major index), reading the
    previous step's seeds only. Returns (D, seed (row, col) per pixel, −1 where none)."""
    h, w = z.shape
    slope = np.broadcast_to(np.asarray(slope, dtype=float), (h, w))
    sy, sx = (float(v) for v in sampling)

    def value(i, j, s):
        si, sj = divmod(s, w)
        dy = (i - si) * sy
        dx = (j - sj) * sx
        d = float(np.sqrt(dy * dy + dx * dx))
        if d == 0.0:
            return float(z[si, sj])
        m = float(slope[si, sj])
        if floor_slope is not None:
            a = -(dx * float(floor_normal[si, sj, 0]) - dy * float(floor_normal[si, sj, 1])) / d
            if a > 0.0:
                a = min(a, 1.0)
                m = (1.0 - a) * m + a * float(floor_slope[si, sj])
        return float(z[si, sj]) - m * d

    seed = [[i * w + j if z[i, j] > -np.inf else -1 for j in range(w)] for i in range(h)]
    for k in steps:
        new = [[-1] * w for _ in range(h)]
        for i in range(h):
            for j in range(w):
                best = seed[i][j]
                best_c = value(i, j, best) if best >= 0 else -np.inf
                for qi in (i - k, i, i + k):
                    for qj in (j - k, j, j + k):
                        if 0 <= qi < h and 0 <= qj < w and seed[qi][qj] >= 0:
                            s = seed[qi][qj]
                            c = value(i, j, s)
                            if c > best_c or (c == best_c and s < best):
                                best, best_c = s, c
                new[i][j] = best
        seed = new
    flat = np.array(seed, dtype=np.int64)
    d = np.full((h, w), -np.inf)
    for i in range(h):
        for j in range(w):
            if flat[i, j] >= 0:
                d[i, j] = value(i, j, int(flat[i, j]))
    rc = np.stack([flat // w, flat % w], axis=-1)
    rc[flat < 0] = -1
    return d, rc


def d3d_top_left_covered(tri, width, height):
    """(H, W) bool: the pixel centres Direct3D's triangle rasterization rules put in ``tri``.

    ``tri``: three (x, y) vertices in Direct3D's render-target coordinates (x right, y down
    from the upper-left corner, pixel (col, row) centred at (col + ½, row + ½)), given as
    anything :class:`fractions.Fraction` takes exactly; rows of the result top to bottom. Exact
    rational arithmetic, written from the rule's words (D3D11.3 functional specification
    §3.4.2.1; "Rasterization Rules (Direct3D 9)"), not from any edge-function bias: a centre
    strictly inside is covered; a centre on an edge is covered when that edge is a **top** edge
    — exactly horizontal and above the other edges (the third vertex has larger y) — or a
    **left** edge — not exactly horizontal, with the triangle on its right (a step in +x from
    the edge goes into the triangle: the third vertex lies on the same side of the edge's line
    as a point one unit to the right of the edge); a centre on two edges (a vertex) is covered
    when both are top or left edges. Either winding; a degenerate triangle covers nothing."""
    from fractions import Fraction
    p = [(Fraction(x), Fraction(y)) for x, y in tri]

    def side(a, b, c):     # sign of the cross product (b − a) × (c − a)
        v = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        return (v > 0) - (v < 0)

    if side(*p) == 0:
        return np.zeros((height, width), np.bool_)
    edges = []
    for k in range(3):
        a, b, c = p[k], p[(k + 1) % 3], p[(k + 2) % 3]
        if a[1] == b[1]:
            owned = c[1] > a[1]                                  # top: the others below
        else:
            right = ((a[0] + b[0]) / 2 + 1, (a[1] + b[1]) / 2)  # one unit right of the edge
            owned = side(a, b, c) == side(a, b, right)           # left: triangle to the right
        edges.append((a, b, side(a, b, c), owned))
    out = np.zeros((height, width), np.bool_)
    for row in range(height):
        for col in range(width):
            q = (Fraction(2 * col + 1, 2), Fraction(2 * row + 1, 2))
            inside = True
            for a, b, s, owned in edges:
                t = side(a, b, q)
                if t == -s or (t == 0 and not owned):
                    inside = False
                    break
            out[row, col] = inside
    return out


# --- multisample coverage (tests/test_msaa.py's twin, tests/test_msaa_clipsurface.py's oracles)

def sample_grid(positions, width, height):
    """Every sample of every pixel, y up (array row 0 is the picture's bottom row).

    ``positions`` ``(S, 2)`` in 1/16 pixel, y down from the pixel's upper-left corner (the
    specifications' own numbers). Returns ``SX, SY`` int64 ``(H, W, S)`` in 1/256 pixel (pixel
    centres at multiples of 256, the snapped vertices' unit) and ``FX, FY`` float64 ``(H, W, S)``
    in pixels.
    """
    pos = np.asarray(positions, np.int64)
    px, py = np.meshgrid(np.arange(width), np.arange(height))    # py: picture-up row index
    SX = (px[..., None] << 8) + (pos[:, 0] - 8) * 16
    SY = (py[..., None] << 8) + (8 - pos[:, 1]) * 16
    FX = px[..., None] + 0.5 + (pos[:, 0] - 8) / 16.0
    FY = py[..., None] + 0.5 + (8 - pos[:, 1]) / 16.0
    return SX, SY, FX, FY


def sample_coverage(X, Y, face, SX, SY, rule="llvmpipe"):
    """The samples ``(SX, SY)`` (:func:`sample_grid`) the triangle ``face`` of the snapped vertices
    ``X, Y`` (1/256 px, y up) covers: exact integer edge functions, a sample on an edge owned by
    the fill rule (``"llvmpipe"``: left and bottom-horizontal edges, y up; else left and
    top-horizontal) → bool ``(H, W, S)``; None for a zero-area triangle."""
    a, b, c = face
    ids = [a, b, c]
    area = (X[b] - X[a]) * (Y[c] - Y[a]) - (X[c] - X[a]) * (Y[b] - Y[a])
    if area == 0:
        return None
    if area < 0:
        ids = [a, c, b]
    cov = np.ones(SX.shape, bool)
    for k in range(3):
        p, q = ids[(k + 1) % 3], ids[(k + 2) % 3]
        dx, dy = X[q] - X[p], Y[q] - Y[p]
        e = dx * (SY - Y[p]) - dy * (SX - X[p])
        owns = dy < 0 or (dy == 0 and (dx > 0 if rule == "llvmpipe" else dx < 0))
        cov &= (e > 0) | ((e == 0) & owns)
    return cov


def sample_plane_depth(xw, yw, zw, face, FX, FY):
    """The depth plane of ``face`` through its unsnapped window positions ``xw, yw`` and depths
    ``zw`` at the samples ``(FX, FY)`` (:func:`sample_grid`), float64, clamped to [0, 1]."""
    a, b, c = face
    x0, y0, x1, y1, x2, y2 = xw[a], yw[a], xw[b], yw[b], xw[c], yw[c]
    den = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
    l1 = ((FX - x0) * (y2 - y0) - (x2 - x0) * (FY - y0)) / den
    l2 = ((x1 - x0) * (FY - y0) - (FX - x0) * (y1 - y0)) / den
    return np.clip(zw[a] + l1 * (zw[b] - zw[a]) + l2 * (zw[c] - zw[a]), 0.0, 1.0)
