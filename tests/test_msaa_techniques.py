"""Edge maps and cutaways on multisampled G-buffers, the halos' refusal (issue 44, items 2–3;
docs/edges.md, docs/cutaway.md, docs/halos4d.md "Multisampling")."""

import numpy as np
import pytest

import refraster as r
from refraster.camera import look_at, perspective
from refraster.cutaway import render_cutaway, render_cutaway_samples
from refraster.edges import edge_map, edge_map_samples
from refraster.sample_rate import window_shift
from refraster.scenes import solid

W, H = 64, 48
VIEW = look_at((3.0, 2.5, 4.0), (0.0, 0.5, 0.0))
PROJ = perspective(35.0, W / H, 1.0, 20.0)


@pytest.fixture(scope="module")
def building():
    m = solid("building")
    return m, np.array([m.vertices.min(axis=0), m.vertices.max(axis=0)])


def _frame(mesh, samples, **raster):
    return r.render_samples(mesh, view=VIEW, proj=PROJ, width=W, height=H,
                            raster=r.RasterState(samples=samples, **raster))


# --- a slow, obvious twin of the paper's operator (MATH.md §3.2) ---------------------------

def _naive_gbuffer(normal, eye, ids, near, far):
    cov = ids >= 0
    n = np.where(cov[..., None], 0.5 * normal.astype(np.float32) + np.float32(0.5),
                 np.float32(0.5)).astype(np.float32)
    z = np.where(cov, np.clip((np.where(cov, eye.astype(np.float64), far) - near) / (far - near),
                              0.0, 1.0), 1.0).astype(np.float32)
    return n, z, ids


def _naive_edges(n, z, ids):
    """E_N = 1 − clamp(½(n_A·n_H + n_C·n_F)) on object pixels, E_Z = 1 − (1 − ½|z_A − z_H|)²
    (1 − ½|z_C − z_F|)², clamp-to-edge, pixel by pixel."""
    h, w = z.shape
    out = np.zeros((h, w, 4))
    d = 2.0 * n.astype(np.float64) - 1.0
    for y in range(h):
        for x in range(w):
            ym, yp, xm, xp = max(y - 1, 0), min(y + 1, h - 1), max(x - 1, 0), min(x + 1, w - 1)
            if ids[y, x] >= 0:
                s = 0.5 * (d[ym, xm] @ d[yp, xp] + d[ym, xp] @ d[yp, xm])
                out[y, x, :3] = 1.0 - min(max(s, 0.0), 1.0)
            a = 1.0 - 0.5 * abs(float(z[ym, xm]) - float(z[yp, xp]))
            b = 1.0 - 0.5 * abs(float(z[ym, xp]) - float(z[yp, xm]))
            out[y, x, 3] = 1.0 - a * a * b * b
    return out


def test_one_sample_is_the_papers_edge_map_bit_for_bit(building):
    mesh, box = building
    fb = r.render(mesh, view=VIEW, proj=PROJ, width=W, height=H)
    want = edge_map(fb, bounds=box)
    for mode in ("per_sample", "resolved"):
        got = edge_map_samples(_frame(mesh, 1), bounds=box, view=VIEW,
                               sampling=r.GBufferSampling(mode))
        assert np.array_equal(got.edge_map, want), mode


def test_per_sample_and_resolved_against_the_twin(building):
    mesh, box = building
    frame = _frame(mesh, 4)
    from refraster.edges import fit_near_far
    near, far = fit_near_far(VIEW, bounds=box)
    gbs = [_naive_gbuffer(frame.normal[:, :, s], frame.eye_depth[:, :, s],
                          frame.object_id[:, :, s], near, far) for s in range(4)]
    per = np.mean([_naive_edges(*g) for g in gbs], axis=0)
    got = edge_map_samples(frame, near=near, far=far)
    assert np.abs(got.edge_map - per).max() < 2e-6
    for s in range(4):
        assert np.abs(got.samples[:, :, s] - _naive_edges(*gbs[s])).max() < 2e-6
    avg_n = np.mean([g[0].astype(np.float64) for g in gbs], axis=0).astype(np.float32)
    avg_z = np.mean([g[1].astype(np.float64) for g in gbs], axis=0).astype(np.float32)
    res = edge_map_samples(frame, near=near, far=far,
                           sampling=r.GBufferSampling("resolved", "average"))
    assert np.abs(res.edge_map - _naive_edges(avg_n, avg_z, gbs[0][2])).max() < 2e-6
    zero = edge_map_samples(frame, near=near, far=far, sampling=r.GBufferSampling("resolved"))
    assert np.abs(zero.edge_map - _naive_edges(*gbs[0])).max() < 2e-6


def test_the_two_modes_are_different_pictures(building):
    mesh, box = building
    frame = _frame(mesh, 4)
    per = edge_map_samples(frame, bounds=box, view=VIEW).edge_map
    zero = edge_map_samples(frame, bounds=box, view=VIEW,
                            sampling=r.GBufferSampling("resolved")).edge_map
    diff = np.abs(per - zero)
    assert (diff > 1 / 255).mean() > 0.01 and diff.max() > 0.2
    # per sample, a step edge's strength takes the fractions of the samples that see it
    assert len(np.unique(np.round(per[..., 3] * 4, 5) % 1)) > 1


def test_window_shift_is_the_allowances_sample_shift():
    from refraster.golden.allowances.samples import sample_shift
    for pos in ((6, 2), (14, 6), (2, 10), (10, 14), (0, 15)):
        assert np.array_equal(window_shift(pos, 96, 72), sample_shift(pos, 96, 72))


def test_a_sample_is_the_moved_frame_at_its_pixel_centre(building):
    """The per-sample cutaway's construction: the frame moved by minus a sample's offset shows,
    at its pixel centres, what render_samples shows at that sample."""
    mesh, _ = building
    frame = _frame(mesh, 4)
    from refraster.raster.samples import pattern
    agree = total = 0
    for s, pos in enumerate(pattern(r.RasterState(samples=4))):
        moved = r.render(mesh, view=VIEW, proj=window_shift(pos, W, H) @ PROJ, width=W, height=H)
        agree += int((moved.prim_id == frame.prim_id[:, :, s]).sum())
        total += moved.prim_id.size
    assert agree / total > 0.999


@pytest.fixture(scope="module")
def shells():
    from refraster.golden.technique_scenes import _cutaway_variant_scene, cutaway_options
    sc = _cutaway_variant_scene("jfa")
    named = {d.name: d.mesh for d in sc.draws}
    return ([named["interest"]], [named["outer_shells"]],
            dict(**sc.camera.kwargs, **cutaway_options(sc.parameters)))


def test_one_sample_cutaway_is_the_papers(shells):
    interest, secondary, kw = shells
    want = render_cutaway(interest, secondary, **kw)
    for mode in ("per_sample", "resolved"):
        got = render_cutaway_samples(interest, secondary, raster=r.RasterState(), **kw,
                                     sampling=r.GBufferSampling(mode))
        assert np.array_equal(got.image, want.image)
        assert np.array_equal(got.frames[0].cutaway_depth, want.cutaway_depth)


def test_cutaway_modes(shells):
    interest, secondary, kw = shells
    st = r.RasterState(samples=4)
    per = render_cutaway_samples(interest, secondary, raster=st, **kw)
    res = render_cutaway_samples(interest, secondary, raster=st, **kw,
                                 sampling=r.GBufferSampling("resolved", "sample_zero"))
    d = per.stack("cutaway_depth")
    # per sample each sample has its own surface; resolved, the samples share the pixel's
    assert np.any(d[:, :, 1] != d[:, :, 0])
    rd = res.stack("cutaway_depth")
    assert all(np.array_equal(rd[:, :, s], rd[:, :, 0]) for s in range(4))
    # resolved from sample 0: sample 0's surface is the per-sample one
    assert np.array_equal(rd[:, :, 0], d[:, :, 0])
    assert np.array_equal(per.frames[0].image, res.frames[0].image)
    assert (np.abs(per.image - res.image) > 1 / 255).any()
    want = np.mean([f.image.astype(np.float64) for f in per.frames], axis=0)
    assert np.array_equal(per.image, want.astype(np.float32))


@pytest.mark.parametrize("call, message", [
    (lambda: r.GBufferSampling("per_pixel"), "sampling.mode must be one of"),
    (lambda: r.GBufferSampling("resolved", "median"), "sampling.resolve must be one of"),
])
def test_sampling_values_refuse_in_one_line(call, message):
    with pytest.raises(ValueError, match=message) as e:
        call()
    assert "\n" not in str(e.value)


def test_techniques_refuse_resolve_modes_without_meaning(building, shells):
    mesh, box = building
    with pytest.raises(ValueError, match=r"sampling.resolve must be one of average, "
                                         r"sample_zero for edge maps, got 'max'"):
        edge_map_samples(_frame(mesh, 4), bounds=box, view=VIEW,
                         sampling=r.GBufferSampling("resolved", "max"))
    interest, secondary, kw = shells
    with pytest.raises(ValueError, match="for cutaways, got 'average'"):
        render_cutaway_samples(interest, secondary, raster=r.RasterState(samples=4), **kw,
                               sampling=r.GBufferSampling("resolved", "average"))
    with pytest.raises(TypeError, match="sampling must be a refraster.GBufferSampling"):
        edge_map_samples(_frame(mesh, 4), bounds=box, view=VIEW, sampling="per_sample")


def test_halos_refuse_samples_in_one_line():
    import refraster.halos4d as h
    with pytest.raises(ValueError) as e:
        h.render_halos(h.figure1_scene(n=4), width=8, height=8, slices=2,
                       raster=r.RasterState(samples=4))
    assert str(e.value).startswith("raster.samples must be 1 for refraster.halos4d")
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="raster.samples must be 1"):
        h.render_halos_pair(h.figure1_scene(n=4), width=8, height=8, slices=2,
                            raster=r.RasterState(samples=2))
    h.render_halos(h.figure1_scene(n=4), width=8, height=8, slices=2, raster=r.RasterState())


def test_the_gallery_shows_a_multisampled_picture_per_technique(tmp_path):
    from refraster.gallery import multisample as g
    items = g.picture("edges", "edges", tmp_path, True) + \
        g.picture("cutaway", "Adaptive cutaways", tmp_path, True)
    assert [i.filename for i in items] == ["edges/edges_building_msaa.png",
                                          "cutaway_shells_msaa.png"]
    assert all((tmp_path / i.filename).is_file() for i in items)
    assert all("differ on" in i.caption for i in items)
    assert g.picture("halos4d", "halos", tmp_path, True) == []
    from refraster.gallery.halos4d import NO_MSAA
    assert "refuses raster.samples > 1" in NO_MSAA
