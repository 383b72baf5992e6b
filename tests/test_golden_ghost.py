"""The cutaway's ghost lines in the golden (issue 20, item 4;
refraster/golden/allowances/ghosts.py):
per-pixel opacity intervals from D's interval, the occluder's and the line's depth range.

Both directions: ghost buffers recomputed over every accepted flooding variant's D (float64 and
float32 floods; the line arithmetic of refraster.cutaway.lines, the occluder of the golden
frame) pass; a ghost pixel faded by 0.25 or a line pixel moved away fails ``refraster golden
compare`` naming the pixel. llvmpipe's GL_LINES ghost (diamond exit, depth at one point of the
line) passes in tests/test_gl_techniques.py.
"""

import subprocess
import sys

import numpy as np
import pytest

from refraster import RasterState, golden

CUT = "cutaway_shells"


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    out = tmp_path_factory.mktemp("ghost") / "g"
    golden.generate(out, [CUT])
    return out


def _buffers(gold):
    with np.load(gold / CUT / "buffers.npz", allow_pickle=False) as z:
        return {k: z[k].copy() for k in z.files}


def _bounds(gold):
    with np.load(gold / CUT / "tolerance.npz", allow_pickle=False) as z:
        return z["ghost_lo"], z["ghost_hi"]


def _zero(gold):
    """Where α may also be 0 (no fragment is sure there)."""
    with np.load(gold / CUT / "tolerance.npz", allow_pickle=False) as z:
        return z["ghost_zero"]


def _write(root, buffers):
    (root / CUT).mkdir(parents=True)
    np.savez(root / CUT / "buffers.npz", **buffers)
    return root


def _compare(gold, cand):
    p = subprocess.run([sys.executable, "-m", "refraster.golden.cli", "golden", "compare",
                        str(gold), str(cand), "--scene", CUT], capture_output=True, text=True)
    return p.returncode, p.stdout + p.stderr


def _ghost_over(scene, b, d_ndc):
    """The ghost buffer refraster draws over the cutaway surface ``d_ndc`` (the golden frame's
    occluder: its visible object of interest)."""
    from refraster.cutaway.lines import feature_segments, ghost_alpha
    p, cam = scene.parameters, scene.camera
    secondary = [d.mesh for d in scene.draws if d.name in p["secondary"]]
    n_sec = len(secondary)
    segs = feature_segments(secondary, view=cam.view, proj=cam.proj,
                            crease_angle=p["crease_angle"])
    ooi = (b["prim_id"] >= 0) & (b["object_id"] >= n_sec)
    occ = np.where(ooi, 2.0 * b["depth"].astype(np.float64) - 1.0, np.inf)
    return ghost_alpha(segs, view=cam.view, proj=cam.proj, width=cam.width, height=cam.height,
                       cutaway_ndc=d_ndc, g_max=p["ghost_distance"], fade=p["ghost_fade"],
                       occluder_depth=occ)


def _gl_lines_ghost(scene, b, point):
    """A GL_LINES ghost buffer drawn in NumPy as a GPU would: one fragment per column (x-major)
    or row (y-major), where the line crosses the column's (row's) centre line, its depth at
    ``point`` ("foot": GL's foot of the pixel centre; "centre": the crossing, llvmpipe's)."""
    from refraster.cutaway.lines import feature_segments, segment_pieces
    from refraster.cutaway.surface import ndc_to_eye_depth
    p, cam = scene.parameters, scene.camera
    h, w = cam.height, cam.width
    secondary = [d.mesh for d in scene.draws if d.name in p["secondary"]]
    segs = feature_segments(secondary, view=cam.view, proj=cam.proj,
                            crease_angle=p["crease_angle"])
    *_, (ends, zends, _) = segment_pieces(segs, view=cam.view, proj=cam.proj, width=w,
                                          height=h, window=True)
    n_sec = len(secondary)
    ooi = (b["prim_id"] >= 0) & (b["object_id"] >= n_sec)
    occ = np.where(ooi, 2.0 * b["depth"].astype(np.float64) - 1.0, np.inf)
    d = 2.0 * b["cutaway_depth"].astype(np.float64) - 1.0
    e = lambda z: ndc_to_eye_depth(np.clip(z, -1.0, 1.0), np.asarray(cam.proj, np.float64))
    g = float(p["ghost_distance"])
    out = np.zeros((h, w))
    for (xa, ya, xb, yb), (za, zb) in zip(ends, zends):
        dx, dy = xb - xa, yb - ya
        xmaj = abs(dx) >= abs(dy)
        ua, ub, va, du, dv = (xa, xb, ya, dx, dy) if xmaj else (ya, yb, xa, dy, dx)
        for k in range(int(np.ceil(min(ua, ub) - 0.5)), int(np.ceil(max(ua, ub) - 0.5))):
            t_c = (k + 0.5 - ua) / du
            j = int(np.floor(va + t_c * dv))
            r, c = (j, k) if xmaj else (k, j)
            if not (0 <= r < h and 0 <= c < w):
                continue
            t = t_c if point == "centre" else (
                ((c + 0.5 - xa) * dx + (r + 0.5 - ya) * dy) / (dx * dx + dy * dy))
            z = za + t * (zb - za)
            gap = max(e(d[r, c]) - e(z), 0.0)
            if z < min(d[r, c], occ[r, c]) and gap < g:
                a = min(max(1.0 - gap / g, 0.0), 1.0) if p.get("ghost_fade", True) else 1.0
                out[r, c] = max(out[r, c], a)
    return out.astype(np.float32)


def test_the_allowance_is_not_vacuous(gold):
    b = _buffers(gold)
    lo, hi = _bounds(gold)
    zero = _zero(gold)
    g = b["ghost"]
    assert ((g >= lo) & (g <= hi) | (zero & (g == 0))).all()
    assert ((lo > 0.25) & ~zero).sum() >= 20        # pixels a line surely reaches
    # where a fragment may be present, 0 or at least the least a drawn one has: 0 alone is not
    # the lower bound everywhere (the realistic teeth, docs/tolerance.md)
    assert ((lo > 0.25) & zero).sum() >= 20
    cov = b["prim_id"] >= 0
    assert (hi[cov] == 0).mean() > 0.6      # no line can reach most covered pixels


@pytest.mark.parametrize("arithmetic", ["float64", "float32"])
def test_ghosts_over_every_accepted_flood_pass(gold, tmp_path, arithmetic):
    """Specificity: the ghost lines drawn over D flooded with every accepted variant (refraster's
    float64 flood, or float32 arithmetic as a shader) pass the golden's ghost check."""
    from flood_f32 import flood_f32
    from refraster import render
    from refraster.cutaway.surface import cutaway_surface
    from refraster.golden.compare.run import compare
    scene = golden.available_scenes()[CUT].build()
    p, cam = scene.parameters, scene.camera
    b = _buffers(gold)
    draws = [d for d in scene.draws if d.name in p["interest"]]
    rear = render([d.mesh for d in draws], **cam.kwargs, model=[d.model for d in draws],
                  raster=RasterState(depth_func="greater", clear_depth=0.0))
    differs = 0
    for variant in p["accepted_variants"]:
        if arithmetic == "float32":
            d = flood_f32(rear.depth, rear.object_id >= 0, scene, variant).astype(np.float64)
        else:
            d = cutaway_surface(rear.depth, rear.object_id, proj=cam.proj, view=cam.view,
                                angle=p["angle"], variant=variant,
                                perspective_compensation=p["perspective_compensation"],
                                edge_compression=p["edge_compression"])
        ghost = _ghost_over(scene, b, d)
        differs += int((ghost != b["ghost"]).sum())
        root = _write(tmp_path / variant, {**b, "ghost": ghost})
        result = compare(gold, root, mode="tolerant", scenes=[CUT], buffers=["ghost"])
        assert result.exit_code == 0, (variant, result.failures()[:5])
    assert differs > 0      # the candidates differ from the golden: the allowance is used


def test_a_faded_ghost_pixel_fails_naming_it(gold, tmp_path):
    b = _buffers(gold)
    lo, _ = _bounds(gold)
    rr, cc = np.argwhere(lo > 0.3)[0]
    b["ghost"][rr, cc] = b["ghost"][rr, cc] - np.float32(0.25) if b["ghost"][rr, cc] - 0.25 \
        < lo[rr, cc] else np.float32(0.0)
    code, out = _compare(gold, _write(tmp_path / "c", b))
    assert code == 1, out
    line = [x for x in out.splitlines() if f"{CUT}/ghost: bounds" in x][0]
    assert f"[[{rr}, {cc}]]" in line, line


def test_a_moved_ghost_pixel_fails_naming_it(gold, tmp_path):
    """A line pixel moved three pixels away from every line: FAIL naming where it landed (and
    where it left, when a line surely reaches that pixel)."""
    b = _buffers(gold)
    lo, hi = _bounds(gold)
    g = b["ghost"]
    src = np.argwhere((lo > 0.3) & ~_zero(gold))[0]
    free = (hi == 0)
    far = np.ones_like(free)
    for di in range(-3, 4):
        for dj in range(-3, 4):
            far &= np.roll(free, (di, dj), axis=(0, 1))
    dst = np.argwhere(far & (b["prim_id"] >= 0))[0]
    g[tuple(dst)] = g[tuple(src)]
    g[tuple(src)] = 0.0
    code, out = _compare(gold, _write(tmp_path / "c", b))
    assert code == 1, out
    line = [x for x in out.splitlines() if f"{CUT}/ghost: bounds" in x][0]
    assert "2 of" in line and f"[{src[0]}, {src[1]}]" in line and f"[{dst[0]}, {dst[1]}]" in line, \
        line


def test_a_maybe_drawn_pixel_is_zero_or_drawn(gold, tmp_path):
    """Where a fragment may or may not be drawn (``ghost_zero``), α is 0 or at least the least a
    drawn fragment has: 0 passes, a value between 0 and ``ghost_lo`` fails naming the pixel."""
    b = _buffers(gold)
    lo, hi = _bounds(gold)
    r, c = np.argwhere((lo > 0.25) & _zero(gold) & (b["prim_id"] >= 0))[0]
    b["ghost"][r, c] = 0.0
    code, out = _compare(gold, _write(tmp_path / "a", b))
    assert code == 0, out
    b["ghost"][r, c] = lo[r, c] * 0.5
    code, out = _compare(gold, _write(tmp_path / "b", b))
    line = [x for x in out.splitlines() if f"{CUT}/ghost: bounds" in x][0]
    assert code == 1 and f"[{r}, {c}]" in line and "or 0" in line, out


@pytest.mark.parametrize("point", ["foot", "centre"])
def test_gl_lines_evaluated_at_either_point_pass(gold, tmp_path, point):
    """Specificity for the GPU's line rule: GL_LINES drawn in NumPy (one fragment per column
    or row where the line crosses its centre line) with each fragment's depth at GL's foot of
    the pixel centre or at that crossing (llvmpipe's point) pass; neither is refraster's
    chord maximum."""
    from refraster.golden.compare.run import compare
    scene = golden.available_scenes()[CUT].build()
    b = _buffers(gold)
    ghost = _gl_lines_ghost(scene, b, point)
    assert (ghost != b["ghost"]).sum() > 50 and (ghost > 0).sum() > 100
    root = _write(tmp_path / point, {**b, "ghost": ghost})
    result = compare(gold, root, mode="tolerant", scenes=[CUT], buffers=["ghost"])
    assert result.exit_code == 0, result.failures()[:5]
