"""G-buffer finalization: from the visible primitive and barycentrics to eye depth, normal and
ids, and (on demand) a simple shade, per pixel (parallel over rows; each row writes only
itself)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._config import IJIT, PJIT
from ._prefetch import prefetch_row
from ._stream import fill_stretch, stream_fence

#: Shading constants of the default colour: ambient, diffuse, specular weight, exponent.
AMBIENT, DIFFUSE, SPECULAR, SHININESS = 0.18, 0.72, 0.22, 48


@njit(**IJIT)
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


#: How many columns ahead of the pixel in hand :func:`_prefetch_ahead` names the rows a
#: pixel will read: its face's vertices (and smooth normals) at ``PREFETCH_NEAR``, its
#: ``faces`` row at ``PREFETCH_FAR`` (read by then, so the near prefetch finds it in cache).
#: A dense mesh (every pixel its own face: 1.3M faces at 1024×768) took ~30 % less time in
#: finalize with them (8 and 16; 4–8 and 16–32 did about as well).
PREFETCH_NEAR = 8
PREFETCH_FAR = 16
#: The kernels prefetch only when there is at least one face per ``PREFETCH_ELEMENTS``
#: elements of the face image (short runs of a face: the gathers wait). With longer runs the
#: rows come in time anyway and the hint costs: 1 thread, 82k faces, 4 samples (3.1M elements)
#: 19.1 ms against 18.9 without; the 1× image (0.8M) 5.2 against 5.5, 1.3M faces at 4×
#: 27.5 against 35.9.
PREFETCH_ELEMENTS = 16


@njit(**IJIT)
def _prefetch_ahead(prim_global, r, c, w, faces, vertices, vnormals, smooth):
    """Prefetch the rows :func:`_face_corners` (and a smooth normal) will read for the faces
    of row ``r``'s pixels ``PREFETCH_NEAR`` and ``PREFETCH_FAR`` columns after ``c`` (a hint:
    no output changes)."""
    gf = prim_global[r, min(c + PREFETCH_FAR, w - 1)]
    if gf >= 0:
        prefetch_row(faces, gf)
    gn = prim_global[r, min(c + PREFETCH_NEAR, w - 1)]
    if gn >= 0:
        for q in range(3):
            v = faces[gn, q]
            prefetch_row(vertices, v)
            if smooth:
                prefetch_row(vnormals, v)


@njit(**IJIT)
def _face_corners(g, vertices, faces):
    """The three corners of face ``g``: ``(ax, ay, az, bx, by, bz, cx, cy, cz)``, loaded once
    per run of a face's pixels by :func:`finalize` and :func:`shade` (of ``vnormals`` for
    ``vertices``: its three vertex normals)."""
    i0 = faces[g, 0]
    i1 = faces[g, 1]
    i2 = faces[g, 2]
    return (vertices[i0, 0], vertices[i0, 1], vertices[i0, 2],
            vertices[i1, 0], vertices[i1, 1], vertices[i1, 2],
            vertices[i2, 0], vertices[i2, 1], vertices[i2, 2])


@njit(**IJIT)
def _at(b0, b1, b2, ax, ay, az, bx, by, bz, cx, cy, cz):
    """The object-space position (float64) at barycentrics ``(b0, b1, b2)`` of a face with
    corners ``a, b, c``; :func:`_surface` takes it through the draw call's model-view rows
    for :func:`finalize` and :func:`shade` (the same bits)."""
    px = (b0 * ax + b1 * bx) + b2 * cx
    py = (b0 * ay + b1 * by) + b2 * cy
    pz = (b0 * az + b1 * bz) + b2 * cz
    return px, py, pz


@njit(**IJIT)
def _eye_normal(k, nx, ny, nz, nmat):
    """``(nx, ny, nz)`` through draw call ``k``'s normal matrix, normalized (float64)."""
    mx = (nmat[k, 0, 0] * nx + nmat[k, 0, 1] * ny) + nmat[k, 0, 2] * nz
    my = (nmat[k, 1, 0] * nx + nmat[k, 1, 1] * ny) + nmat[k, 1, 2] * nz
    mz = (nmat[k, 2, 0] * nx + nmat[k, 2, 1] * ny) + nmat[k, 2, 2] * nz
    length = np.sqrt(mx * mx + my * my + mz * mz)
    if length > 0.0:
        mx /= length
        my /= length
        mz /= length
    return mx, my, mz


@njit(**IJIT)
def _flat_normal(g, k, vertices, faces, nmat):
    """Unit eye-space face normal (float64) of face ``g`` of draw call ``k``: the same at
    every pixel of the face (it does not depend on the barycentrics)."""
    i0 = faces[g, 0]
    i1 = faces[g, 1]
    i2 = faces[g, 2]
    ax = vertices[i1, 0] - vertices[i0, 0]
    ay = vertices[i1, 1] - vertices[i0, 1]
    az = vertices[i1, 2] - vertices[i0, 2]
    bx = vertices[i2, 0] - vertices[i0, 0]
    by = vertices[i2, 1] - vertices[i0, 1]
    bz = vertices[i2, 2] - vertices[i0, 2]
    nx = ay * bz - az * by
    ny = az * bx - ax * bz
    nz = ax * by - ay * bx
    return _eye_normal(k, nx, ny, nz, nmat)


@njit(**IJIT)
def _smooth_normal(k, b0, b1, b2, vn, nmat):
    """Unit eye-space normal (float64) of draw call ``k`` interpolated at barycentrics
    ``(b0, b1, b2)`` from a face's three vertex normals ``vn`` (its rows of the normals array:
    :func:`_face_corners` of ``vnormals``)."""
    n0x, n0y, n0z, n1x, n1y, n1z, n2x, n2y, n2z = vn
    nx = (b0 * n0x + b1 * n1x) + b2 * n2x
    ny = (b0 * n0y + b1 * n1y) + b2 * n2y
    nz = (b0 * n0z + b1 * n1z) + b2 * n2z
    return _eye_normal(k, nx, ny, nz, nmat)


@njit(**IJIT)
def _face_normals(vertices, faces, face_offsets, nmat, fnormal):
    """Every face's :func:`_flat_normal` into ``fnormal`` (F, 3) float64 (each face writes
    only its row)."""
    for g in prange(face_offsets[face_offsets.shape[0] - 1]):
        k = _object_of(face_offsets, g)
        mx, my, mz = _flat_normal(g, k, vertices, faces, nmat)
        fnormal[g, 0] = mx
        fnormal[g, 1] = my
        fnormal[g, 2] = mz


#: Flat normals are computed once per face (into a per-call array, from the vertices as they
#: are when the kernel runs) instead of once per run of a face's pixels in a row when the frame
#: has at least this many pixels per face: a face normal costs about what a pixel's does, and a
#: frame's covered pixels are a fraction of its pixels. Same float64 expression either way, so
#: the same bits.
FACE_NORMAL_PIXELS = 16


@njit(**IJIT)
def _run_normal(g, k, per_face, fnormal, vertices, faces, nmat):
    """The flat normal of face ``g`` (draw call ``k``) for a run of its pixels: from ``fnormal``
    where computed per face (``per_face``), else :func:`_flat_normal` here — once per run of
    the face's pixels in a row, not once per pixel (the same expression, so the same bits)."""
    if per_face:
        return fnormal[g, 0], fnormal[g, 1], fnormal[g, 2]
    return _flat_normal(g, k, vertices, faces, nmat)


@njit(**IJIT)
def _surface(bary, r, c, k, corners, fm, flat, vn, mv, nmat):
    """The float64 eye-space position and unit eye-space normal of a face of draw call ``k``
    at pixel ``(r, c)``'s barycentrics: what :func:`finalize` rounds (it uses z only; LLVM drops
    x and y there) and :func:`shade` lights, one expression (the same bits). ``corners``: the
    face's :func:`_face_corners`; ``fm``: its flat normal (:func:`_run_normal`) where ``flat``,
    else the normal is interpolated per pixel from its vertex normals ``vn``
    (:func:`_face_corners` of ``vnormals``, loaded once per run: :func:`_smooth_normal`). The
    position comes before the normal's branch, in the order the kernels had written it out:
    so both compile to the same instructions as before this helper (with the position after
    the branch, LLVM recomputed the model-view row's address per pixel; finalize ~1.1x)."""
    b0 = np.float64(bary[r, c, 0])
    b1 = np.float64(bary[r, c, 1])
    b2 = np.float64(bary[r, c, 2])
    ax, ay, az, bx, by, bz, cx, cy, cz = corners
    px, py, pz = _at(b0, b1, b2, ax, ay, az, bx, by, bz, cx, cy, cz)
    ex = ((mv[k, 0, 0] * px + mv[k, 0, 1] * py) + mv[k, 0, 2] * pz) + mv[k, 0, 3]
    ey = ((mv[k, 1, 0] * px + mv[k, 1, 1] * py) + mv[k, 1, 2] * pz) + mv[k, 1, 3]
    ez = ((mv[k, 2, 0] * px + mv[k, 2, 1] * py) + mv[k, 2, 2] * pz) + mv[k, 2, 3]
    if flat:
        mx, my, mz = fm
    else:
        mx, my, mz = _smooth_normal(k, b0, b1, b2, vn, nmat)
    return ex, ey, ez, mx, my, mz


def per_face_normals(n_faces, height, width, smooth):
    """Whether :func:`finalize` and :func:`shade` take flat normals per face (see
    :data:`FACE_NORMAL_PIXELS`)."""
    return (not smooth) and int(n_faces) * FACE_NORMAL_PIXELS <= int(height) * int(width)


@njit(**IJIT)
def _background_end(prim, r, c, w):
    """The end (exclusive) of the run of background (``< 0``) in row ``r`` of the face image
    ``prim`` from column ``c``: eight columns a step while their AND is negative (all eight
    are), then one by one."""
    ur = np.uint64(r)
    e = np.uint64(c)
    uw = np.uint64(w)
    while e + np.uint64(8) <= uw:
        m = (prim[ur, e] & prim[ur, e + np.uint64(1)] & prim[ur, e + np.uint64(2)]
             & prim[ur, e + np.uint64(3)] & prim[ur, e + np.uint64(4)]
             & prim[ur, e + np.uint64(5)] & prim[ur, e + np.uint64(6)]
             & prim[ur, e + np.uint64(7)])
        if m >= 0:
            break
        e += np.uint64(8)
    while e < uw and prim[ur, e] < 0:
        e += np.uint64(1)
    return np.int64(e)


@njit(**IJIT)
def _background_run(r, a, b, ids, rbg, prim_id, object_id, eye_depth, normal, r_depth,
                    r_front, r_bary, clear_depth, stream):
    """The background (+inf, 0, −1, −1; with ``rbg`` the rasterizer's ``clear_depth``,
    False, 0) in columns ``a … b − 1`` of row ``r``: :func:`finalize`'s fill. The indices are
    unsigned: no negative-index fix-up per store."""
    r = np.uint64(r)
    ua = np.uint64(a)
    ub = np.uint64(b)
    if ids:
        fill_stretch(prim_id[r], ua, ub, np.int32(-1), stream)
    fill_stretch(object_id[r], ua, ub, np.int32(-1), stream)
    fill_stretch(eye_depth[r], ua, ub, np.float32(np.inf), stream)
    fill_stretch(normal[r].reshape(-1), np.uint64(3) * ua, np.uint64(3) * ub, np.float32(0.0),
                 stream)
    if rbg:
        fill_stretch(r_depth[r], ua, ub, clear_depth, stream)
        fill_stretch(r_front[r], ua, ub, False, stream)
        fill_stretch(r_bary[r].reshape(-1), np.uint64(3) * ua, np.uint64(3) * ub,
                     np.float32(0.0), stream)


@njit(**PJIT)
def finalize(prim_global, bary, vertices, faces, vnormals, smooth, face_offsets, mv, nmat,
             fnormal, per_face, fill_bg, stream, eye_depth, normal, prim_id, object_id, spans,
             r_depth, r_front, r_bary, clear_depth):
    """Eye depth, normal and ids of the covered pixels of the face image ``prim_global``
    (global face index, int32: :data:`FACE_IMAGE_DTYPES`; ``≥ 0``); the background
    (+inf, 0, −1, −1) too when ``fill_bg``, else the caller has filled it. ``per_face``
    (flat normals only): the face normals are computed first, once per face, into ``fnormal``
    (F, 3) float64 scratch (:func:`per_face_normals`). ``spans`` (H, 2) int64: each row's
    first and last covered column (``(0, −1)`` for a row with none), the record a reused
    framebuffer clears from on its next frame (:func:`clear_spans`). ``prim_id`` of shape
    ``(0, 0)``: the ids are not written (one draw call, whose ids are the face image itself,
    which the caller hands out instead: ``render_samples``). ``r_depth``, ``r_front``,
    ``r_bary`` (the rasterizer's depth, facing and barycentrics, ``(H, W[, 3])``): with
    ``fill_bg``, their background (``clear_depth``, False, 0) is written in the same sweep
    (the tile pass wrote only the pixels a fragment won); shape ``(0, …)``: not asked."""
    if per_face:
        _face_normals(vertices, faces, face_offsets, nmat, fnormal)
    h, w = prim_global.shape
    ids = prim_id.shape[0] != 0
    pf = faces.shape[0] * PREFETCH_ELEMENTS >= h * w
    rbg = fill_bg and r_depth.shape[0] != 0
    for r in prange(h):
        first = np.int64(w)
        end = np.int64(-1)
        # what depends on the face only (its draw call, id, vertices, the model-view rows
        # and, per face, its normal) is loaded once per run of pixels of one face, not once
        # per pixel; the per-pixel arithmetic is the same in shade (the same bits)
        last = np.int64(-1)
        k = np.int64(0)
        pid = np.int64(0)
        ax = ay = az = bx = by = bz = cx = cy = cz = 0.0
        fm0 = fm1 = fm2 = 0.0
        vn = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        c = np.int64(-1)
        while c < w - 1:
            c += 1
            g = prim_global[r, c]
            if g < 0:
                # a run of background: found eight columns a step and, with fill_bg, each
                # array's stretch filled by a loop of its own (stores only, which LLVM
                # vectorizes). Pixel by pixel, among the covered pixels' branches, this took
                # 8.6 ms of one thread for a 1024×768 4× sample image with nothing covered,
                # against 4.6 (NumPy's fills of the same arrays: 3.7)
                e = _background_end(prim_global, r, c + 1, w)
                if fill_bg:
                    _background_run(r, c, e, ids, rbg, prim_id, object_id, eye_depth,
                                    normal, r_depth, r_front, r_bary, clear_depth, stream)
                c = e - 1
                continue
            if g != last:
                last = g
                if pf:
                    _prefetch_ahead(prim_global, r, c, w, faces, vertices, vnormals, smooth)
                k = _object_of(face_offsets, g)
                pid = g - face_offsets[k]
                ax, ay, az, bx, by, bz, cx, cy, cz = _face_corners(g, vertices, faces)
                if smooth:
                    vn = _face_corners(g, vnormals, faces)   # its vertex normals
                else:
                    fm0, fm1, fm2 = _run_normal(g, k, per_face, fnormal, vertices, faces, nmat)
            if first == w:
                first = c
            end = c
            if ids:
                prim_id[r, c] = pid
            object_id[r, c] = k
            _, _, ez, mx, my, mz = _surface(
                bary, r, c, k, (ax, ay, az, bx, by, bz, cx, cy, cz), (fm0, fm1, fm2),
                not smooth, vn, mv, nmat)
            eye_depth[r, c] = np.float32(-ez)
            normal[r, c, 0] = np.float32(mx)
            normal[r, c, 1] = np.float32(my)
            normal[r, c, 2] = np.float32(mz)
        if end < 0:
            first = 0
        spans[r, 0] = first
        spans[r, 1] = end
        if stream:
            stream_fence()   # after the row's streaming stores (_background_run)


@njit(**PJIT)
def clear_spans(spans, after, clear_depth, depth, face, front, bary, eye_depth, normal, prim_id,
                object_id):
    """Clear a reused framebuffer's pixels that its previous frame covered: columns
    ``spans[r, 0] … spans[r, 1]`` of each row ``r`` (:func:`finalize`'s record), the only ones
    that may hold anything but the clear values. In two steps around the frame's passes, so
    that a pixel the new frame covers again is written once, not cleared and written:
    ``after=False`` (before the tile pass) resets the face image there to −1; ``after=True``
    (after :func:`finalize`) writes the clear values (depth ``clear_depth``, facing False,
    barycentrics 0, eye depth +inf, normal 0, ids −1) into the pixels of those spans that the
    new frame left uncovered (face image still −1). ``bary`` and ``normal`` are (H, 3·W)
    views."""
    for r in prange(spans.shape[0]):
        c0 = spans[r, 0]
        c1 = spans[r, 1] + 1
        if not after:
            for c in range(c0, c1):
                face[r, c] = -1
            continue
        for c in range(c0, c1):
            if face[r, c] >= 0:
                continue
            depth[r, c] = clear_depth
            front[r, c] = False
            eye_depth[r, c] = np.inf
            prim_id[r, c] = -1
            object_id[r, c] = -1
            for j in range(3 * c, 3 * c + 3):
                bary[r, j] = 0.0
                normal[r, j] = 0.0


@njit(**PJIT)
def shade(prim_global, bary, vertices, faces, vnormals, smooth, face_offsets, mv, nmat,
          fnormal, per_face, n_shaded, palette, background, color):
    """The default colour: a two-sided headlight Blinn–Phong shade of the palette colour of
    each pixel's draw call, from the same float64 position and normal :func:`finalize` rounds;
    ``background`` where nothing was drawn and where the visible face is not one of the first
    ``n_shaded`` (a caller that shades those itself). Every element of ``color`` is written.
    ``fnormal``, ``per_face``: as in :func:`finalize` (computed here again, from the vertices
    as they are now)."""
    if per_face:
        _face_normals(vertices, faces, face_offsets, nmat, fnormal)
    h, w = prim_global.shape
    pf = faces.shape[0] * PREFETCH_ELEMENTS >= h * w   # as in finalize
    for r in prange(h):
        # a face's draw call, vertices and (per face) normal loaded once per run of its
        # pixels, as in finalize; the per-pixel arithmetic is finalize's, in its order
        last = np.int64(-1)
        k = np.int64(0)
        ax = ay = az = bx = by = bz = cx = cy = cz = 0.0
        fm0 = fm1 = fm2 = 0.0
        vn = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        c = np.int64(-1)
        while c < w - 1:
            c += 1
            g = prim_global[r, c]
            if g < 0:
                # a run of background, as in finalize
                e = _background_end(prim_global, r, c + 1, w)
                for q in range(np.uint64(c), np.uint64(e)):
                    color[np.uint64(r), q, 0] = background[0]
                    color[np.uint64(r), q, 1] = background[1]
                    color[np.uint64(r), q, 2] = background[2]
                c = e - 1
                continue
            if g >= n_shaded:
                for j in range(3):
                    color[r, c, j] = background[j]
                continue
            if g != last:
                last = g
                if pf:
                    _prefetch_ahead(prim_global, r, c, w, faces, vertices, vnormals, smooth)
                k = _object_of(face_offsets, g)
                ax, ay, az, bx, by, bz, cx, cy, cz = _face_corners(g, vertices, faces)
                if smooth:
                    vn = _face_corners(g, vnormals, faces)   # its vertex normals
                else:
                    fm0, fm1, fm2 = _run_normal(g, k, per_face, fnormal, vertices, faces, nmat)
            ex, ey, ez, mx, my, mz = _surface(
                bary, r, c, k, (ax, ay, az, bx, by, bz, cx, cy, cz), (fm0, fm1, fm2),
                not smooth, vn, mv, nmat)
            # light at the eye, so the half vector is the view vector
            vl = np.sqrt(ex * ex + ey * ey + ez * ez)
            ndv = 1.0
            if vl > 0.0:
                ndv = -(mx * ex + my * ey + mz * ez) / vl
            d = min(abs(ndv), 1.0)
            d2 = d * d
            d4 = d2 * d2
            d8 = d4 * d4
            d16 = d8 * d8
            s = d16 * (d16 * d16)  # d ** SHININESS without a pow call
            pk = k % palette.shape[0]
            for j in range(3):
                v = palette[pk, j] * (AMBIENT + DIFFUSE * d) + SPECULAR * s
                color[r, c, j] = np.float32(min(max(v, 0.0), 1.0))


#: The face image dtypes :func:`finalize` and :func:`shade` are compiled for, one
#: specialisation each (every other input goes through :func:`readonly`, so nothing else
#: varies): int32, the face image of ``render`` and the sample image of ``render_samples``
#: (``(H, W·S)``): half the bytes of an int64 one for the tile passes to write and both kernels
#: to read; at most 2³¹ faces (:data:`refraster.raster.rasterizer.MAX_FACES`). ``_build``
#: converts any other (the allowances' face lists). ``tests/test_gbuffer_paths.py`` fails on
#: any other specialisation.
FACE_IMAGE_DTYPES = (np.int32,)


def readonly(a):
    """``a`` as a read-only C-contiguous array (a view; a copy only if ``a`` is not
    C-contiguous): the kernels above take every input array this way, so each compiles one
    specialisation whether a caller's array is writeable or not."""
    if not a.flags.writeable and a.flags.c_contiguous:
        return a
    v = np.ascontiguousarray(a).view()
    v.flags.writeable = False
    return v
