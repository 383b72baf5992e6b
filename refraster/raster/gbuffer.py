"""G-buffer finalization: from the visible primitive and barycentrics to eye depth, normal,
ids and a simple shade, per pixel (parallel over rows; each row writes only itself)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._config import JIT, PJIT

#: Shading constants of the default colour: ambient, diffuse, specular weight, exponent.
AMBIENT, DIFFUSE, SPECULAR, SHININESS = 0.18, 0.72, 0.22, 48.0


@njit(**JIT)
def _object_of(face_offsets, g):
    lo = 0
    hi = face_offsets.shape[0] - 2
    while lo < hi:
        mid = (lo + hi + 1) >> 1
        if face_offsets[mid] <= g:
            lo = mid
        else:
            hi = mid - 1
    return lo


@njit(**PJIT)
def finalize(prim_global, bary, vertices, faces, vnormals, smooth, face_offsets, mv, nmat,
             palette, background, eye_depth, normal, prim_id, object_id, color):
    h, w = prim_global.shape
    for r in prange(h):
        for c in range(w):
            g = prim_global[r, c]
            if g < 0:
                eye_depth[r, c] = np.inf
                prim_id[r, c] = -1
                object_id[r, c] = -1
                for j in range(3):
                    normal[r, c, j] = 0.0
                    color[r, c, j] = background[j]
                continue
            k = _object_of(face_offsets, g)
            prim_id[r, c] = g - face_offsets[k]
            object_id[r, c] = k
            i0 = faces[g, 0]
            i1 = faces[g, 1]
            i2 = faces[g, 2]
            b0 = np.float64(bary[r, c, 0])
            b1 = np.float64(bary[r, c, 1])
            b2 = np.float64(bary[r, c, 2])
            p = np.zeros(3)
            for j in range(3):
                p[j] = (b0 * vertices[i0, j] + b1 * vertices[i1, j]) + b2 * vertices[i2, j]
            e = np.zeros(3)
            for j in range(3):
                e[j] = ((mv[k, j, 0] * p[0] + mv[k, j, 1] * p[1]) + mv[k, j, 2] * p[2]) \
                    + mv[k, j, 3]
            eye_depth[r, c] = np.float32(-e[2])
            n = np.zeros(3)
            if smooth:
                for j in range(3):
                    n[j] = (b0 * vnormals[i0, j] + b1 * vnormals[i1, j]) + b2 * vnormals[i2, j]
            else:
                ax = vertices[i1, 0] - vertices[i0, 0]
                ay = vertices[i1, 1] - vertices[i0, 1]
                az = vertices[i1, 2] - vertices[i0, 2]
                bx = vertices[i2, 0] - vertices[i0, 0]
                by = vertices[i2, 1] - vertices[i0, 1]
                bz = vertices[i2, 2] - vertices[i0, 2]
                n[0] = ay * bz - az * by
                n[1] = az * bx - ax * bz
                n[2] = ax * by - ay * bx
            ne = np.zeros(3)
            for j in range(3):
                ne[j] = (nmat[k, j, 0] * n[0] + nmat[k, j, 1] * n[1]) + nmat[k, j, 2] * n[2]
            length = np.sqrt(ne[0] * ne[0] + ne[1] * ne[1] + ne[2] * ne[2])
            if length > 0.0:
                for j in range(3):
                    ne[j] /= length
            for j in range(3):
                normal[r, c, j] = np.float32(ne[j])
            # two-sided headlight: light at the eye, so the half vector is the view vector
            vl = np.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
            ndv = 1.0
            if vl > 0.0:
                ndv = -(ne[0] * e[0] + ne[1] * e[1] + ne[2] * e[2]) / vl
            d = min(abs(ndv), 1.0)
            s = d ** SHININESS
            pk = k % palette.shape[0]
            for j in range(3):
                v = palette[pk, j] * (AMBIENT + DIFFUSE * d) + SPECULAR * s
                color[r, c, j] = np.float32(min(max(v, 0.0), 1.0))
