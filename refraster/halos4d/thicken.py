"""View-dependent thickening, prisms → tetrahedra, and the halo depth (Wang et al. Sec. 4.3–4.5).

Thickening (Eq. 1–2, MATH.md §5.3 [fix]): ``n = t1_3D × t2_3D`` is **normalized** (the paper's
unnormalized n would make the halo thickness depend on the parametrization), and where
``|n| < ε·|t1|·|t2|`` (edge-on view, projection folds, singular parametrization such as a
knot's poles) it falls back to the normalized sum of the area-weighted normals of the projected
3D faces around the vertex; if that vanishes too, to +z. The thickened vertex array holds the
lower copy ``v − ρ n̂`` (t = 0) at indices ``0 … n−1`` and the upper copy ``v + ρ n̂`` (t = 1) at
``n … 2n−1``.

Tetrahedra (MATH.md §5.5): the global vertex-index rule, so neighbouring prisms split every
shared quad by the same diagonal without extra vertices.

Halo depth (Eq. 3, MATH.md §5.4): ``d_new = d_orig + max(0, |2t − 1| − δt)·δd``, evaluated per
fragment (|·| is not linear).
"""

from __future__ import annotations

import numpy as np

from .._validate import as_float_array, as_index_array, as_real

__all__ = ["thickening_normals", "thicken", "prism_tetrahedra", "halo_depth", "NORMAL_EPS"]

#: Relative threshold of the |t1 × t2| fallback.
NORMAL_EPS = 1e-6


def _face_normal_sum(points, faces):
    a = points[faces[:, 0]]
    fn = np.cross(points[faces[:, 1]] - a, points[faces[:, 2]] - a)   # 2·area·unit normal
    acc = np.zeros_like(points)
    for k in range(3):
        np.add.at(acc, faces[:, k], fn)
    return acc


def thickening_normals(points, tangents, faces):
    """Unit thickening directions n̂ (Eq. 1, normalized; fallback of MATH.md §5.3).

    Parameters
    ----------
    points : (V, 3) float
        Projected vertices (3D screen space).
    tangents : (V, 2, 3) float
        Projected tangents t1, t2.
    faces : (F, 3) int
        Only used by the fallback.

    Returns
    -------
    normals : (V, 3) float64, unit length.
    n_fallback : int
        How many vertices used the face-normal fallback (including the +z last resort).
    """
    p = as_float_array(points, "points", shape=(None, 3))
    t = as_float_array(tangents, "tangents", shape=(p.shape[0], 2, 3))
    f = as_index_array(faces, "faces", shape=(None, 3), upper=max(p.shape[0], 1))
    n = np.cross(t[:, 0], t[:, 1])
    ln = np.linalg.norm(n, axis=1)
    scale = np.linalg.norm(t[:, 0], axis=1) * np.linalg.norm(t[:, 1], axis=1)
    bad = ~(ln > NORMAL_EPS * scale) | (scale == 0.0)
    out = np.zeros_like(n)
    out[~bad] = n[~bad] / ln[~bad, None]
    if bad.any():
        fb = _face_normal_sum(p, f)[bad]
        lf = np.linalg.norm(fb, axis=1)
        ok = lf > 0.0
        fb[ok] /= lf[ok, None]
        fb[~ok] = (0.0, 0.0, 1.0)
        out[bad] = fb
    return out, int(bad.sum())


def thicken(points, normals, rho):
    """Offset surfaces ``v ± ρ n̂`` (Eq. 2): ``(vertices (2V, 3), t (2V,))``, lower copy first."""
    p = as_float_array(points, "points", shape=(None, 3))
    n = as_float_array(normals, "normals", shape=p.shape)
    rho = as_real(rho, "rho", lo=0.0, lo_open=True)
    verts = np.concatenate([p - rho * n, p + rho * n])
    t = np.concatenate([np.zeros(len(p)), np.ones(len(p))])
    return verts, t


def prism_tetrahedra(faces, n_vertices):
    """Split each prism (face × [lower, upper]) into three tetrahedra (MATH.md §5.5).

    Parameters
    ----------
    faces : (F, 3) int
        Triangles over vertices ``0 … n_vertices−1``; the upper copy of vertex i is
        ``i + n_vertices``. Faces with a repeated vertex are rejected.
    n_vertices : int

    Returns
    -------
    (3F, 4) int64
        Tetrahedra ``3f, 3f+1, 3f+2`` come from face f. With the face's vertices sorted
        ``a < b < c`` (global index) and ``⁺`` the upper copy: ``(a, b, c, c⁺)``,
        ``(a, b, c⁺, b⁺)``, ``(a, a⁺, b⁺, c⁺)``.

    Notes
    -----
    Every quad side is split along the diagonal from its lower-index bottom vertex to the
    higher-index top vertex (a–b⁺, b–c⁺, a–c⁺), which is Dompierre et al.'s rule "diagonal through
    the smallest global index" for the numbering i / i + n; it depends only on the quad's own
    vertices, so two prisms sharing a quad split it the same way, and a prism's minimum vertex
    carries two diagonals, so the pattern is never the cyclic one that needs a Steiner point
    (Wang et al. Fig. 4(c)–(d) are unnecessary). Orientation: when the upper copy lies on the side
    of the face normal (right-hand rule of the face as given) of an untwisted prism, all three
    tetrahedra have positive signed volume ``det[v1−v0, v2−v0, v3−v0] > 0``.
    """
    if isinstance(n_vertices, bool) or not isinstance(n_vertices, (int, np.integer)):
        raise TypeError(f"n_vertices must be an int, got {type(n_vertices).__name__}")
    if n_vertices < 3:
        raise ValueError(f"n_vertices must be at least 3, got {n_vertices}")
    f = as_index_array(faces, "faces", shape=(None, 3), upper=int(n_vertices))
    s = np.sort(f, axis=1)
    if np.any((s[:, 0] == s[:, 1]) | (s[:, 1] == s[:, 2])):
        bad = int(np.count_nonzero((s[:, 0] == s[:, 1]) | (s[:, 1] == s[:, 2])))
        raise ValueError(f"faces has {bad} degenerate triangle(s) with a repeated vertex")
    a, b, c = s[:, 0], s[:, 1], s[:, 2]
    n = int(n_vertices)
    tets = np.stack([
        np.stack([a, b, c, c + n], axis=1),
        np.stack([a, b, c + n, b + n], axis=1),
        np.stack([a, a + n, b + n, c + n], axis=1),
    ], axis=1)
    # sorting by an odd permutation reverses the face's orientation: swap two tet vertices back
    odd = _odd_permutation(f)
    tets[odd] = tets[odd][:, :, [1, 0, 2, 3]]
    return tets.reshape(-1, 4)


def _odd_permutation(f):
    """True where sorting a face's three (distinct) indices is an odd permutation."""
    inversions = ((f[:, 0] > f[:, 1]).astype(int) + (f[:, 0] > f[:, 2]) + (f[:, 1] > f[:, 2]))
    return (inversions % 2) == 1


def halo_depth(d_orig, t, delta_t, delta_d):
    """Eq. 3: ``d_new = d_orig + max(0, |2t − 1| − δt)·δd`` (elementwise, float64)."""
    d = as_float_array(d_orig, "d_orig")
    tt = as_float_array(t, "t")
    delta_t = as_real(delta_t, "delta_t", lo=0.0, hi=1.0)
    delta_d = as_real(delta_d, "delta_d", lo=0.0)
    return d + np.maximum(0.0, np.abs(2.0 * tt - 1.0) - delta_t) * delta_d
