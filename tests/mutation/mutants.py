"""The curated mutants of issue 30: realistic single-point bugs, each with the test files to run.

A mutant replaces one exact snippet of ``file`` (it must occur exactly once, or the runner refuses
it) and, where the formula has a twin (a NumPy or brute-force copy in ``tests/naive.py`` or a test
file, a second engine, a per-element form), the same misreading in the twin (``twin``: extra
``(file, old, new)`` edits). ``module`` groups the mutants; ``fast`` marks the one mutant per
module that the CI subset runs (``run.py --fast``), with only the tests named in ``ci``.

The first seventeen are the ones issue 30 reports (the four it does not name are filled in
with bugs of the same kind); the rest cover every module the issue lists.
"""

from __future__ import annotations

from dataclasses import dataclass, field

HAND = ["tests/test_hand_worked.py"]
RASTER = ["tests/test_raster.py"] + HAND
LDI = ["tests/test_ldi.py"] + HAND
CLIP = ["tests/test_clipsurface.py", "tests/test_clipsurface_fused.py"] + HAND
CLIP_ALL = CLIP + ["tests/test_clipsurface_render.py"]
OFFSET = ["tests/test_offsetmaps.py"] + HAND
EDGES = ["tests/test_edges.py"]
NPR = ["tests/test_npr.py"]
CUT = ["tests/test_cutaway.py", "tests/test_cutaway_render.py"] + HAND
H4 = ["tests/test_halos4d_geometry.py", "tests/test_halos4d_eq3.py",
      "tests/test_halos4d_render.py", "tests/test_halos4d_defaults.py",
      "tests/test_halos4d_options.py"] + HAND
GOLD = ["tests/test_golden.py", "tests/test_golden_tolerant.py"] + HAND

PRIM = "refraster/raster/primitive.py"
RAST = "refraster/raster/rasterizer.py"
NAIVE = "tests/naive.py"
EDGE = "refraster/edges/operators.py"
TEDGE = "tests/test_edges.py"
FLOOD = "refraster/cutaway/flood.py"
SURF = "refraster/cutaway/surface.py"
HREN = "refraster/halos4d/render.py"
THICK = "refraster/halos4d/thicken.py"
ACORE = "refraster/golden/allowances/core.py"
AEDGE = "refraster/golden/allowances/edges.py"
ALAYER = "refraster/golden/allowances/layers.py"
AGHOST = "refraster/golden/allowances/ghosts.py"
ARITH = ["tests/test_allowance_arithmetic.py"]


@dataclass(frozen=True)
class Mutant:
    name: str
    module: str
    doc: str
    file: str
    old: str
    new: str
    tests: list
    twin: list = field(default_factory=list)
    fast: bool = False
    #: With ``--fast`` (CI): the tests to run instead of ``tests`` (the ones that kill it), so
    #: that the subset stays within a few minutes.
    ci: list = field(default_factory=list)


MUTANTS = [
    # ------------------------------------------------------------- the seventeen of issue 30
    Mutant("ldi_parity_strict", "ldi", "parity counts layers with `<` instead of `≤`",
           "refraster/ldi.py", "if depth[i] <= tr:", "if depth[i] < tr:",
           LDI + ["tests/test_clipsurface_fused.py"], fast=True,
           ci=["tests/test_ldi.py::test_parity_on_a_layer_entry_closed_exit_open"]),
    Mutant("cutaway_slope_tan", "cutaway", "uncompensated slope P00·tan θ instead of P00·cot θ",
           SURF, "return np.full(np.shape(z_ndc), proj[0, 0]) / tan",
           "return np.full(np.shape(z_ndc), proj[0, 0]) * tan", CUT),
    Mutant("clip_vertex_on_plane", "raster", "clipper drops a vertex exactly on the plane "
           "(`>=` → `>`)", PRIM, "            if di >= 0.0:\n                for c in range(7):",
           "            if di > 0.0:\n                for c in range(7):", RASTER),
    Mutant("snap_floor", "raster", "vertex snapping by floor instead of rint (kernel and naive)",
           PRIM, "np.int64(np.rint((xw - half) * scale)), np.int64(np.rint((yw - half) * scale))",
           "np.int64(np.floor((xw - half) * scale)), np.int64(np.floor((yw - half) * scale))",
           RASTER, twin=[(NAIVE, "int(np.rint((xw - half) * s)), int(np.rint((yw - half) * s))",
                          "int(np.floor((xw - half) * s)), int(np.floor((yw - half) * s))")],
           fast=True,
           ci=["tests/test_hand_worked.py::test_vertex_snapping_rounds_to_the_nearest_subpixel"]),
    Mutant("bary_screen_space", "raster", "screen-space instead of perspective-correct "
           "barycentrics (kernel and naive)", RAST,
           "    q0 = l0 * iw0\n    q1 = l1 * iw1\n    q2 = l2 * iw2",
           "    q0 = l0 * 1.0\n    q1 = l1 * 1.0\n    q2 = l2 * 1.0", RASTER,
           twin=[(NAIVE, "q = [lk * iw for lk, iw in zip(lam, IW)]",
                  "q = [lk * 1.0 for lk, iw in zip(lam, IW)]")]),
    Mutant("diag_normal_twice", "edges", "diagonal normal operator with A·H twice (no C·F) "
           "(kernel and twin)", EDGE,
           "_dot(n, ym, xm, yp, xp, encoded) + _dot(n, ym, xp, yp, xm, encoded)",
           "_dot(n, ym, xm, yp, xp, encoded) + _dot(n, ym, xm, yp, xp, encoded)", EDGES,
           twin=[(TEDGE, '_dot(s["A"], s["H"]) + _dot(s["C"], s["F"])',
                  '_dot(s["A"], s["H"]) + _dot(s["A"], s["H"])')], fast=True,
           ci=["tests/test_edges.py::test_default_edge_map_is_the_papers_normal_operator_on_a_normal_ramp"]),
    Mutant("sobel_transposed", "edges", "Sobel G_x and G_y swapped (kernel and twin)", EDGE,
           "    gx = (zc + 2.0 * ze + zh) - (za + 2.0 * zd + zf)\n    return gy, gx",
           "    gx = (zc + 2.0 * ze + zh) - (za + 2.0 * zd + zf)\n    return gx, gy", EDGES,
           twin=[(TEDGE, '    gx = (s["C"] + 2.0 * s["E"] + s["H"]) - (s["A"] + 2.0 * s["D"] + '
                  's["F"])\n    return gy, gx',
                  '    gx = (s["C"] + 2.0 * s["E"] + s["H"]) - (s["A"] + 2.0 * s["D"] + '
                  's["F"])\n    return gx, gy')]),
    Mutant("eq3_halved", "halos4d", "Eq. 3's drop-off δd halved (both engines and halo_depth)",
           HREN, "dn = d + max(0.0, u - delta_t) * delta_d",
           "dn = d + max(0.0, u - delta_t) * (0.5 * delta_d)", H4,
           twin=[(HREN, "np.minimum.at(min_d, pix, d + np.maximum(0.0, u - delta_t) * delta_d)",
                  "np.minimum.at(min_d, pix, d + np.maximum(0.0, u - delta_t) * (0.5 * delta_d))"),
                 (THICK, "np.abs(2.0 * tt - 1.0) - delta_t) * delta_d",
                  "np.abs(2.0 * tt - 1.0) - delta_t) * (0.5 * delta_d)")], fast=True,
           ci=["tests/test_halos4d_geometry.py::test_halo_depth_eq3"]),
    Mutant("eq3_halved_engines", "halos4d", "Eq. 3's drop-off δd halved in both rendering "
           "engines (fused kernel and NumPy reference), not in halo_depth", HREN,
           "dn = d + max(0.0, u - delta_t) * delta_d",
           "dn = d + max(0.0, u - delta_t) * (0.5 * delta_d)", H4,
           twin=[(HREN, "np.minimum.at(min_d, pix, d + np.maximum(0.0, u - delta_t) * delta_d)",
                  "np.minimum.at(min_d, pix, d + np.maximum(0.0, u - delta_t) * (0.5 * delta_d))")]),
    Mutant("clip_height_scale_k0", "clipsurface", "g(P) reads surface 0's height scale S_z for "
           "every surface", "refraster/clipsurface/surfaces.py",
           "+ params[k, 16] * h", "+ params[0, 16] * h", CLIP_ALL, fast=True,
           ci=["tests/test_hand_worked.py::test_clip_mask_of_two_surfaces_by_hand"]),
    Mutant("resolve_less_later", "raster", "depth test LESS passes equal depths (the later of "
           "two equal-depth fragments wins) (kernel and naive)", RAST,
           "    if func == 1:\n        return z < ref", "    if func == 1:\n        return z <= ref",
           RASTER + LDI, twin=[(NAIVE, "if z < depth[row, col]:", "if z <= depth[row, col]:")]),
    Mutant("fill_rule_horizontal", "raster", "fill rule: horizontal-edge tie flipped (owns top, "
           "not bottom) (kernel and naive)", RAST,
           "owns = dy < 0 or (dy == 0 and dx > 0)   # left or bottom edge",
           "owns = dy < 0 or (dy == 0 and dx < 0)   # left or bottom edge", RASTER,
           twin=[(NAIVE, "if rule == \"bottom-left\":\n                        owns = dy < 0 or "
                  "(dy == 0 and dx > 0)", "if rule == \"bottom-left\":\n                        "
                  "owns = dy < 0 or (dy == 0 and dx < 0)")]),
    Mutant("clip_skip_self_any", "clipsurface", "clip test of a cap fragment of surface j "
           "skips every surface k > j, not only j (`k != skip` as `k < skip`; mesh fragments "
           "unaffected): a cap of the first surface is not trimmed by the second",
           "refraster/clipsurface/surfaces.py", "        if enabled[k] and k != skip:",
           "        if enabled[k] and (k < skip or skip < 0):", CLIP_ALL),
    Mutant("compare_skips_bary", "golden", "compare skips the barycentric buffer",
           "refraster/golden/compare/run.py",
           "        for key, spec in entry[\"buffers\"].items():",
           "        for key, spec in [(k, v) for k, v in entry[\"buffers\"].items()\n"
           "                          if k != \"barycentric\"]:", GOLD, fast=True,
           ci=["tests/test_golden.py::test_every_stored_buffer_is_compared"]),
    Mutant("peel_sort_unstable", "ldi", "per-pixel depth sort puts equal depths in reverse draw "
           "order (`>` → `>=`)", "refraster/ldi.py",
           "while j >= a and depth[order[j]] > d:", "while j >= a and depth[order[j]] >= d:", LDI),
    Mutant("offset_no_half_texel", "offsetmaps", "GL_LINEAR without the half-texel shift "
           "(u = s·W instead of s·W − ½)", "refraster/clipsurface/offsetmaps.py",
           "    x = s * width - 0.5\n    y = t * height - 0.5",
           "    x = s * width\n    y = t * height", OFFSET + CLIP, fast=True,
           ci=["tests/test_hand_worked.py::test_texel_centres_return_the_texel_under_each_wrap_mode"]),
    Mutant("npr_composite_inverted", "npr", "compositing reads the edge strength as the "
           "intensity (E and 1 − E swapped, MATH.md §3.1)", "refraster/edges/npr.py",
           "inner = (1.0 - e_n) * s + e_n * ci", "inner = e_n * s + (1.0 - e_n) * ci", NPR,
           fast=True,
           ci=["tests/test_npr.py::test_composite_hand_values"]),
    Mutant("jfa_schedule_short", "cutaway", "jump-flood schedule starts at n/4 (the longest "
           "jump dropped)", FLOOD, "    k = n // 2\n", "    k = n // 4\n", CUT, fast=True,
           ci=["tests/test_hand_worked.py::test_jump_schedule_is_half_the_next_power_of_two_down_to_one"]),
    # ------------------------------------------------------------- further mutants
    Mutant("clip_interp_far_end", "raster", "clipper interpolates from the far endpoint on ties "
           "and beyond (`<` → `>`)", PRIM, "if ai < aj or (ai == aj and di >= 0.0):",
           "if ai > aj or (ai == aj and di >= 0.0):", RASTER),
    Mutant("clip_near_plane_sign", "raster", "near clip plane z − w ≥ 0 instead of z + w ≥ 0",
           PRIM, "        return z + w          # near", "        return w - z          # near",
           RASTER),
    Mutant("ldi_peel_coplanar", "ldi", "depth peeling keeps equal-depth duplicates as separate "
           "layers (`>` → `>=`)", "refraster/ldi.py",
           "else d > depth[order[w - 1]]):", "else d >= depth[order[w - 1]]):", LDI),
    Mutant("ldi_texel_row_flip", "ldi", "parity test's texel row not flipped (t up vs row 0 at "
           "the top)", "refraster/ldi.py", "    row = h - 1 - min(int(tt * h), h - 1)",
           "    row = min(int(tt * h), h - 1)", LDI + ["tests/test_clipsurface_fused.py"]),
    Mutant("clip_test_le", "clipsurface", "clip test discards g(P) ≤ 0 instead of g(P) < 0",
           "refraster/clipsurface/surfaces.py",
           "if _g(px, py, pz, params, k, maps, offset, shape, wrap[k]) < 0.0:",
           "if _g(px, py, pz, params, k, maps, offset, shape, wrap[k]) <= 0.0:", CLIP_ALL),
    Mutant("offset_mirror_off_by_one", "offsetmaps", "mirrored_repeat mirrors about the texel "
           "instead of its edge (−m instead of −(1 + m))", "refraster/clipsurface/offsetmaps.py",
           "mirrored = m if m >= 0 else -(1 + m)", "mirrored = m if m >= 0 else -m", OFFSET),
    Mutant("offset_repeat_seam_clamp", "offsetmaps", "repeat wrap clamps the right-hand tap at "
           "the seam instead of wrapping to texel 0", "refraster/clipsurface/offsetmaps.py",
           "i1 = i0 + 1 if i0 + 1 < width else np.int64(0)", "i1 = i0 + 1 if i0 + 1 < width else i0",
           OFFSET + CLIP),
    Mutant("cap_tbn_transposed", "capping", "cap normal turned by the transposed (Û, V̂, N) "
           "basis", "refraster/clipsurface/capping.py",
           "    wx = a * params[k, 3] + b * params[k, 6] + c * params[k, 9]\n"
           "    wy = a * params[k, 4] + b * params[k, 7] + c * params[k, 10]\n"
           "    wz = a * params[k, 5] + b * params[k, 8] + c * params[k, 11]",
           "    wx = a * params[k, 3] + b * params[k, 4] + c * params[k, 5]\n"
           "    wy = a * params[k, 6] + b * params[k, 7] + c * params[k, 8]\n"
           "    wz = a * params[k, 9] + b * params[k, 10] + c * params[k, 11]",
           ["tests/test_clipsurface_render.py", "tests/test_clipsurface_fused.py"] + HAND, fast=True,
           ci=["tests/test_hand_worked.py::test_cap_normal_and_shade_of_a_flat_cap_face_on"]),
    Mutant("cap_shade_no_abs", "capping", "cap shade uses n·v without the absolute value",
           "refraster/clipsurface/capping.py", "ndv = abs(ex * px + ey * py + ez * pz) / vl",
           "ndv = (ex * px + ey * py + ez * pz) / vl",
           ["tests/test_clipsurface_render.py", "tests/test_clipsurface_fused.py"] + HAND),
    Mutant("diag_depth_no_half", "edges", "diagonal depth operator without the ½ on the "
           "differences (kernel and twin)", EDGE,
           "    a = 1.0 - 0.5 * abs(d_ah)\n    b = 1.0 - 0.5 * abs(d_cf)",
           "    a = 1.0 - abs(d_ah)\n    b = 1.0 - abs(d_cf)", EDGES,
           twin=[(TEDGE, "    a = 1.0 - 0.5 * np.abs(d1)\n    b = 1.0 - 0.5 * np.abs(d2)",
                  "    a = 1.0 - np.abs(d1)\n    b = 1.0 - np.abs(d2)")]),
    Mutant("c1_weight_dropped", "edges", "C1 depth operator weighs the right neighbour 1, not 2 "
           "(kernel and twin)", EDGE, "s += 2.0 * abs(np.float64(z[y, xp]) - zx)",
           "s += 1.0 * abs(np.float64(z[y, xp]) - zx)", EDGES,
           twin=[(TEDGE, 't = t + 2.0 * np.abs(s["E"] - x)', 't = t + 1.0 * np.abs(s["E"] - x)')]),
    Mutant("sobel_normal_scale", "edges", "Sobel normal strength divided by 4 instead of 8 "
           "(kernel and twin)", EDGE, "return min(k_n * np.sqrt(s) / 8.0, 1.0)",
           "return min(k_n * np.sqrt(s) / 4.0, 1.0)", EDGES,
           twin=[(TEDGE, "np.minimum(k_n * np.sqrt(total) / 8.0, 1.0)",
                  "np.minimum(k_n * np.sqrt(total) / 4.0, 1.0)")]),
    Mutant("angle_normal_no_half", "edges", "angle normal operator 1 − n·n' instead of "
           "(1 − n·n')/2 (kernel and twin)", EDGE,
           "e = 0.5 * (1.0 - _dot(n, y, x, yy, xx, encoded))",
           "e = 1.0 - _dot(n, y, x, yy, xx, encoded)", EDGES,
           twin=[(TEDGE, '0.5 * (1.0 - _dot(s["X"], s[q]))', '1.0 - _dot(s["X"], s[q])')]),
    Mutant("jfa_candidates_half", "cutaway", "jump-flood candidate columns {0, +k} only (kernel "
           "and naive)", FLOOD, "            for oj in range(-1, 2):",
           "            for oj in range(0, 2):", CUT,
           twin=[(NAIVE, "for qj in (j - k, j, j + k):", "for qj in (j, j + k):")]),
    Mutant("jfa_tie_larger_index", "cutaway", "jump-flood ties go to the larger seed index "
           "(kernel and naive)", FLOOD, "((c == best_c) & (s < best))",
           "((c == best_c) & (s > best))", CUT,
           twin=[(NAIVE, "c == best_c and s < best", "c == best_c and s > best")]),
    Mutant("cutaway_compensated_sign", "cutaway", "compensated slope −(P22 − z)/tan θ instead "
           "of −(P22 + z)/tan θ", SURF, "return -(proj[2, 2] + z_ndc) / tan",
           "return -(proj[2, 2] - z_ndc) / tan", CUT),
    Mutant("floor_y_down", "cutaway", "floor constraint with the screen y axis pointing down "
           "(kernel, exact and naive)", FLOOD,
           "a = -(dx * nx - dy * ny) / (d if d != 0.0 else 1.0)",
           "a = -(dx * nx + dy * ny) / (d if d != 0.0 else 1.0)", CUT,
           twin=[(FLOOD, "a = -(dx * seeds[s, _NX] - dy * seeds[s, _NY]) / d",
                  "a = -(dx * seeds[s, _NX] + dy * seeds[s, _NY]) / d"),
                 (NAIVE, "a = -(dx * float(floor_normal[si, sj, 0]) - dy * "
                  "float(floor_normal[si, sj, 1])) / d",
                  "a = -(dx * float(floor_normal[si, sj, 0]) + dy * "
                  "float(floor_normal[si, sj, 1])) / d")]),
    Mutant("rotation4d_sign", "halos4d", "4D plane rotation turns +b toward +a (sin signs "
           "swapped)", "refraster/halos4d/transforms.py",
           "    r[a, b] = -s\n    r[b, a] = s", "    r[a, b] = s\n    r[b, a] = -s", H4),
    Mutant("project_tangent_sign", "halos4d", "perspective tangent: quotient rule with − "
           "(v·t_w term subtracted)", "refraster/halos4d/transforms.py",
           "depth[:, None, None] + v[:, None, :3] * t[..., 3:4]",
           "depth[:, None, None] - v[:, None, :3] * t[..., 3:4]", H4),
    Mutant("thicken_half_rho", "halos4d", "thickening offsets v ± ρ/2·n̂ (ρ read as the full "
           "thickness)", THICK, "verts = np.concatenate([p - rho * n, p + rho * n])",
           "verts = np.concatenate([p - 0.5 * rho * n, p + 0.5 * rho * n])", H4),
    Mutant("prism_no_orientation_fix", "halos4d", "prism split without the odd-permutation "
           "orientation fix", THICK, "tets[odd] = tets[odd][:, :, [1, 0, 2, 3]]",
           "tets[odd] = tets[odd][:, :, [0, 1, 2, 3]]", H4),
    Mutant("slice_quad_bowtie", "halos4d", "tetrahedron cross-section quad split as a bow tie "
           "(corner order e_ac, e_ad, e_bc, e_bd)", "refraster/halos4d/slicing.py",
           "return 2, (a, c, a, d, b, d, a, c, b, d, b, c)",
           "return 2, (a, c, a, d, b, c, a, c, b, c, b, d)", H4),
    Mutant("slice_alpha_no_two", "halos4d", "per-slice opacity exponent Δz/(w_s·ρ) instead of "
           "Δz/(2·w_s·ρ)", HREN, "(spacing / (2.0 * surface_width * rho))",
           "(spacing / (surface_width * rho))", H4),
    Mutant("golden_deviation_one_way", "golden", "position-deviation compare accepts either "
           "direction (`&` → `|`), as a one-way check would",
           "refraster/golden/compare/metrics.py",
           "            & _matched_within(reference, candidate, thr, radius))",
           "            | _matched_within(reference, candidate, thr, radius))", GOLD),
    Mutant("allowance_across_surfaces", "golden", "allowance step measured across different "
           "surfaces (the same-surface test dropped)", "refraster/golden/allowances/core.py",
           "same = (surface[a] == surface[b]) & (surface[a] >= 0)",
           "same = (surface[a] >= 0) & (surface[b] >= 0)", GOLD),
    # ------------------------------------------------ the allowance arithmetic (issue 42, item 3)
    # each killed by tests/test_allowance_arithmetic.py, which derives the numbers by hand
    Mutant("allow_shift_margin", "allowance", "second-order margin on the value intervals 1.0 "
           "instead of 1.5", ACORE, "SHIFT_MARGIN = 1.5", "SHIFT_MARGIN = 1.0", ARITH),
    Mutant("allow_bary_tol", "allowance", "barycentric budget doubled", ACORE,
           "BARY_TOL = 1e-3", "BARY_TOL = 2e-3", ARITH),
    Mutant("allow_eye_rel", "allowance", "relative eye-depth budget ten times too wide", ACORE,
           "EYE_DEPTH_ABS, EYE_DEPTH_REL = 1e-5, 4e-6", "EYE_DEPTH_ABS, EYE_DEPTH_REL = 1e-5, 4e-5",
           ARITH),
    Mutant("allow_round_inwards", "allowance", "float32 lower bounds rounded inwards",
           ACORE, "lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)",
           "lo32 = np.where(lo32 < lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)", ARITH),
    Mutant("allow_depth_region_may", "allowance", "depth interval applied at \"may\" pixels too",
           ACORE, 'region &= (arrays["coverage"] == MUST) & covered_by(cand, clear_depth,',
           'region &= (arrays["coverage"] >= MAY) & covered_by(cand, clear_depth,', ARITH),
    Mutant("allow_interval_step_inwards", "allowance", "the interval's upper end narrowed by "
           "the quantisation step instead of widened", ACORE,
           '            hi = arrays[spec["hi"]].astype(np.float64) + step\n'
           '            c = cand.astype(np.float64)',
           '            hi = arrays[spec["hi"]].astype(np.float64) - step\n'
           '            c = cand.astype(np.float64)', ARITH),
    Mutant("allow_angle_one_step", "allowance", "normal angle widened by one step, not √3 steps",
           ACORE, 'limit = arrays[spec["angle"]].astype(np.float64) + step * math.sqrt(3.0)',
           'limit = arrays[spec["angle"]].astype(np.float64) + step', ARITH),
    Mutant("allow_face_counts_background", "allowance", "the face check counts a background "
           "candidate pixel as naming a face outside the set", ACORE,
           "return id_may & has & (c >= 0) & (named < 0)", "return id_may & has & (named < 0)",
           ARITH),
    Mutant("allow_coverage_one_way", "allowance", "coverage checks only \"must\" (a covered "
           "\"must not\" pixel passes)", ACORE,
           'outside["coverage"] = ((cov == MUST) & ~cc) | ((cov == MUST_NOT) & cc)',
           'outside["coverage"] = ((cov == MUST) & ~cc)', ARITH, fast=True,
           ci=["tests/test_allowance_arithmetic.py::test_coverage_check_by_hand"]),
    Mutant("guard_no_scene", "allowance", "an empty scene selection is compared (a pass on "
           "nothing)", "refraster/golden/compare/run.py",
           "    if not names:\n        raise GoldenError(\"nothing to compare: \"",
           "    if names is None:\n        raise GoldenError(\"nothing to compare: \"", ARITH),
    Mutant("guard_first_scene_only", "allowance", "the nothing-compared guard looks at the first "
           "scene only", "refraster/golden/compare/run.py",
           'empty = [n for n in names if not manifest["scenes"][n]["buffers"]]',
           'empty = [n for n in names[:1] if not manifest["scenes"][n]["buffers"]]', ARITH),
    Mutant("edges_absdiff_no_zero", "allowance", "|a − b| of overlapping intervals bounded away "
           "from 0", AEDGE, "return 0.0, max(-dlo, dhi)", "return min(-dlo, dhi), max(-dlo, dhi)",
           ARITH),
    Mutant("edges_sq_no_zero", "allowance", "x² of an interval around 0 bounded away from 0",
           AEDGE, "return 0.0, max(lo * lo, hi * hi)",
           "return min(lo * lo, hi * hi), max(lo * lo, hi * hi)", ARITH),
    Mutant("edges_lin_negative_weight", "allowance", "a negative weight keeps the interval's "
           "ends in order", AEDGE, "return wlo + q * phi, whi + q * plo",
           "return wlo + q * plo, whi + q * phi", ARITH),
    Mutant("edges_dot_unclamped", "allowance", "the largest angle between turned normals not "
           "clamped at π", AEDGE, "lo = min(lo, math.cos(min(math.pi, t0 + a)) - ddot)",
           "lo = min(lo, math.cos(t0 + a) - ddot)", ARITH),
    Mutant("edges_dot_free_no_slack", "allowance", "a free pixel's dot product without the "
           "arithmetic slack", AEDGE, "return -1.0 - ddot, 1.0 + ddot", "return -1.0, 1.0", ARITH),
    Mutant("layers_stab_touching", "allowance", "touching depth intervals counted as two "
           "layers", ALAYER, "if starts[q] > point:", "if starts[q] >= point:", ARITH),
    Mutant("layers_alone_touching", "allowance", "an entry whose interval touches another's "
           "must show on its own", ALAYER,
           "if k != i and lo[k] <= hi[i] and hi[k] >= lo[i]:",
           "if k != i and lo[k] < hi[i] and hi[k] > lo[i]:", ARITH),
    Mutant("layers_count_hi_sure_only", "allowance", "the largest layer count omits entries "
           "that may reach the clear depth", ALAYER,
           "            if lo[i] < clear:\n                n_may += 1",
           "            if hi[i] < clear:\n                n_may += 1", ARITH),
    Mutant("ghost_eval_foot_only", "allowance", "a line fragment's depth taken at GL's foot of "
           "the centre only (llvmpipe's centre-line point dropped)", AGHOST,
           "            ts.append(t)\n", "            ts.append(t_f)\n", ARITH),
    Mutant("ghost_foot_moves_untilted", "allowance", "the foot's move under vertex moves without "
           "the line's turn (the 2h/L term)", AGHOST, "(reach(t_f) + 2.0 * h / ln)",
           "reach(t_f)", ARITH),
    Mutant("ghost_major_axis_sure_only", "allowance", "a nearly diagonal line's column centre "
           "line used only where x is surely the major axis", AGHOST,
           "(dx, (cx - xa) / dx, ~ymaj)", "(dx, (cx - xa) / dx, xmaj)", ARITH),
]
