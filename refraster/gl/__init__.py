"""refraster.gl: a GLSL backend for refraster's golden scene packages (optional extra ``gl``).

A GPU team's client of the goldens, written as one: plain ``.glsl`` shaders (``shaders/``,
``#version 330 core``, so the same files run on desktop GL drivers) beside a thin driver
(:mod:`refraster.gl.driver`) on a standalone headless EGL context (moderngl). It reads only the
scene packages of a golden directory (``scene.json``, PLY meshes, ``.npy`` maps:
:mod:`refraster.gl.package`) — never refraster's Python scene objects or kernels, and it imports
nothing else of refraster (``tests/test_gl_backend.py`` scans its imports).

``import refraster`` never imports this subpackage; ``import refraster.gl`` imports no OpenGL
either (the context is created by :class:`refraster.gl.driver.Backend`).

    from refraster.gl.driver import Backend
    with Backend() as gl:
        buffers = gl.render("golden/render_cube/package")   # {name: (H, W[, C]) array}

On the command line: ``refraster golden candidate GOLDEN_DIR --backend gl --out CANDIDATE_DIR``
(docs/backends.md).
"""

__all__ = ["SUPPORTED_TECHNIQUES", "FAULTS", "TECHNIQUE_FAULTS", "CONVENTION_FAULTS",
           "CATALOGUE_FAULTS", "MSAA_FAULTS", "MSAA_TECHNIQUE_FAULTS"]

#: Techniques this backend renders, with what it renders for them.
SUPPORTED_TECHNIQUES = {
    "render": "the G-buffer in one pass with multiple render targets",
    "ldi": "classic depth peeling (one pass per layer)",
    "vds": "the volumetric parity test in a fragment shader over the sprite as a texture array",
    # issue 26 item 1 (refraster/gl/clipsurface.py, shaders/clip.*)
    "clipsurface": "2.5D clip surfaces: Listing 1's discard, caps as the exported displaced "
                   "grid with the parity-test discard, shaded from the derived and user maps",
    # issue 26 (refraster/gl/edges.py)
    "edges": "the edge G-buffer T_G (RGBA8 or float), one full-screen pass with the diagonal / "
             "C1 / Sobel / angle operators into an RGBA8 or float edge map, the width dilation",
    "cutaway": "rear hulls (GREATER), seeds, ping-pong jump flooding with the scene's schedule, "
               "D_dil and cut normals, the clipped G-buffer with cut surfaces, ghost lines",
    # issue 43 (refraster/gl/msaa.py)
    "msaa": "the G-buffer into multisample targets at the context's own sample positions "
            "(which must be the scene's declared pattern), each sample read with texelFetch, "
            "the colour resolved by glBlitFramebuffer",
    "halos4d": "tetrahedra sliced per plane in a geometry shader, Eq. 3's halo depth per "
               "fragment (MIN blending), the surface fragment by depth test, slices "
               "composited back to front with blending",
}

#: Planted faults, each a test-only ``#define`` (never set in normal use): name → (define,
#: what it does). ``Backend(faults=[name, ...])`` switches them on.
FAULTS = {
    "half_pixel": ("FAULT_HALF_PIXEL", "the viewport shifted by half a pixel (vertex stage)"),
    "noperspective": ("FAULT_NOPERSPECTIVE",
                      "eye position, normal and barycentrics interpolated with noperspective"),
    "facing_flipped": ("FAULT_FACING_FLIPPED", "gl_FrontFacing inverted (the G-buffer's "
                                               "facing as if the rows had been flipped)"),
    "peel_no_discard": ("FAULT_PEEL_NO_DISCARD",
                        "depth peeling that does not discard the previous layer"),
    "sprite_rows_flipped": ("FAULT_SPRITE_ROWS_FLIPPED",
                            "the volumetric depth sprite's rows read top-down"),
    "parity_wrong_end": ("FAULT_PARITY_WRONG_END", "the parity count run from the back layer "
                                                   "with the front-to-back early exit"),
    # clip surfaces (issue 26 item 1; shaders/clip.frag)
    "clip_sign_flipped": ("FAULT_CLIP_SIGN", "the clip test's sign flipped (g > 0 discarded)"),
    "offset_t_flipped": ("FAULT_OFFSET_T_FLIPPED", "the offset map's t axis flipped (1 − t)"),
    "cap_no_parity": ("FAULT_CAP_NO_PARITY", "caps drawn without the parity-test discard"),
}

#: Planted faults of the technique passes (issue 26; tests/test_gl_techniques.py), also in
#: :data:`FAULTS`.
TECHNIQUE_FAULTS = {
    # edge maps (shaders/edge_map.frag)
    "one_diagonal": ("FAULT_ONE_DIAGONAL", "the diagonal normal and depth operators with one "
                                           "diagonal (A–H) only"),
    "sobel_transposed": ("FAULT_SOBEL_TRANSPOSED", "the Sobel G_y kernel written transposed "
                                                   "(it equals G_x: edges along x vanish)"),
    # cutaways (refraster/gl/cutaway.py, shaders/cutaway_seed.frag)
    "schedule_truncated": ("FAULT_SCHEDULE_TRUNCATED", "the jump-flooding schedule without its "
                                                       "last 3 passes"),
    "slope_from_theta": ("FAULT_SLOPE_FROM_THETA", "the cutaway slope from tan θ instead of "
                                                   "cot θ"),
    "floor_flipped": ("FAULT_FLOOR_FLIPPED", "the floor constraint's normal with its sign "
                                             "flipped (φ negated: the floor side is not "
                                             "flattened)"),
    # 4D halos (refraster/gl/halos.py, shaders/halo_*.frag)
    "eq3_halved": ("FAULT_EQ3_HALVED", "Eq. 3's drop-off δd halved"),
    "slices_front_to_back": ("FAULT_SLICES_FRONT_TO_BACK", "the slices composited front to "
                                                           "back"),
}
FAULTS.update(TECHNIQUE_FAULTS)

#: Planted faults of the API conventions (issue 39; tests/test_gl_conventions.py), also in
#: :data:`FAULTS`. They are switches of the driver's GL state (the ``#define`` is inert).
CONVENTION_FAULTS = {
    "depth_remap_on_zero_to_one": ("FAULT_DEPTH_REMAP_ON_ZERO_TO_ONE",
                                   "glClipControl's depth mode left at GL_NEGATIVE_ONE_TO_ONE "
                                   "under depth_range 'zero_to_one': GL's remap 0.5·z/w + 0.5 "
                                   "and clipping at z = −w applied to a [0, 1] projection"),
    "reversed_z_less": ("FAULT_REVERSED_Z_LESS", "reversed-Z drawn with the depth test 'less' "
                                                 "('lequal' for 'gequal')"),
    "reversed_z_clear_one": ("FAULT_REVERSED_Z_CLEAR_ONE", "the depth buffer cleared to 1 under "
                                                           "'greater' / 'gequal'"),
    "winding_not_flipped": ("FAULT_WINDING_NOT_FLIPPED", "under the upper-left origin, the "
                                                         "polygon area's sign not negated with "
                                                         "the origin (glFrontFace inverted "
                                                         "there): front and back swap"),
}
FAULTS.update(CONVENTION_FAULTS)

#: Planted faults of the catalogue of GPU bug classes (issue 41; :mod:`refraster.gl.catalogue`,
#: tests/test_conformance_catalogue.py, docs/conformance.md), also in :data:`FAULTS`. Each is
#: the bug itself: a ``#define`` of a shader or a switch of the driver's GL state or upload.
CATALOGUE_FAULTS = {
    # transforms (driver: the matrices of _upload / _write)
    "normal_matrix_modelview": ("FAULT_NORMAL_MATRIX_MODELVIEW", "normals transformed by the "
                                "model-view matrix instead of its inverse transpose"),
    "mirror_compensated": ("FAULT_MIRROR_COMPENSATED", "glFrontFace flipped for a draw whose "
                           "model matrix has a negative determinant (facing judged in object "
                           "space, not by the window winding)"),
    "matrix_row_major": ("FAULT_MATRIX_ROW_MAJOR", "the row-major matrices uploaded without "
                         "the transpose (GL reads them column-major)"),
    "projection_left_handed": ("FAULT_PROJECTION_LEFT_HANDED", "the projection applied to a "
                               "left-handed eye space (eye z negated: the camera looks down "
                               "+z)"),
    # rasterization (shaders/gbuffer.vert, gbuffer.geom, gbuffer.frag; driver upload)
    "subpixel_1bit": ("FAULT_SUBPIXEL_1BIT", "vertices snapped to 1 sub-pixel bit (half-pixel "
                      "grid), below the 4 bits any golden admits"),
    "fill_rule_neither": ("FAULT_FILL_RULE_NEITHER", "a tie rule that gives a pixel centre on "
                          "an edge to neither triangle (cracks along shared edges)"),
    "guard_band_clamp": ("FAULT_GUARD_BAND_CLAMP", "vertices beyond an 8x guard band clamped "
                         "to it instead of clipped (huge triangles change shape)"),
    "near_w_clamped": ("FAULT_NEAR_W_CLAMPED", "clip w clamped to at least 1e-3 (a guard "
                       "against w -> 0 that moves vertices behind the eye)"),
    "degenerate_dropped": ("FAULT_DEGENERATE_DROPPED", "zero-area triangles removed from the "
                           "index buffer at upload (the primitive ids after them shift)"),
    # depth
    "linear_depth_written": ("FAULT_LINEAR_DEPTH_WRITTEN", "the linear eye depth written as "
                             "the window depth"),
    "depth_unorm16_declared_float": ("FAULT_DEPTH_UNORM16", "a 16-bit fixed-point depth buffer "
                                     "where the scene declares float32"),
    "depth_clamp_always": ("FAULT_DEPTH_CLAMP_ALWAYS", "GL_DEPTH_CLAMP enabled where the scene "
                           "does not ask for it (nothing clipped at near and far)"),
    # state
    "cull_face_inverted": ("FAULT_CULL_FACE_INVERTED", "glCullFace front and back swapped"),
    "front_face_inverted": ("FAULT_FRONT_FACE_INVERTED", "glFrontFace CCW and CW swapped"),
    "depth_func_always": ("FAULT_DEPTH_FUNC_ALWAYS", "the depth function left at GL_ALWAYS"),
    "depth_cleared_per_draw": ("FAULT_DEPTH_CLEARED_PER_DRAW", "the depth buffer cleared "
                               "before every draw call (the last draw wins)"),
    # data
    "base_vertex_ignored": ("FAULT_BASE_VERTEX_IGNORED", "draws packed into one vertex buffer, "
                            "their indices used without the base vertex"),
    "index_offset": ("FAULT_INDEX_OFFSET", "the index range read one index late"),
    "index16": ("FAULT_INDEX16", "indices uploaded as 16-bit (truncated past 65,535 "
                "vertices)"),
    "object_id_stale": ("FAULT_OBJECT_ID_STALE", "the object id uniform set for the first "
                        "draw call only"),
    "readback_rows_unflipped": ("FAULT_READBACK_ROWS", "the read-back rows kept bottom-first "
                                "(GL_LOWER_LEFT) as if row 0 were the top"),
    # compositing
    "srgb_encoded": ("FAULT_SRGB_ENCODED", "the linear colour sRGB-encoded before it is "
                     "written to the float colour target"),
    "halo_premultiplied": ("FAULT_HALO_PREMULTIPLIED", "the straight-alpha halo slices "
                           "blended as premultiplied (ONE, ONE_MINUS_SRC_ALPHA)"),
    # technique-specific
    "offset_map_nearest": ("FAULT_OFFSET_MAP_NEAREST", "the offset map filtered NEAREST "
                           "instead of bilinearly"),
    "offset_map_clamped": ("FAULT_OFFSET_MAP_CLAMPED", "the offset map's wrap mode "
                           "clamp-to-edge whatever the surface's wrap"),
    "eq3_sign": ("FAULT_EQ3_SIGN", "Eq. 3's drop-off subtracted (halo depth in front of the "
                 "line)"),
    "ghost_not_depth_tested": ("FAULT_GHOST_NOT_DEPTH_TESTED", "ghost-line fragments not "
                               "tested against the removed layer D"),
}
FAULTS.update(CATALOGUE_FAULTS)

#: Planted faults of multisampling (issue 43; :mod:`refraster.gl.msaa`,
#: tests/test_gl_msaa.py), also in :data:`FAULTS`.
MSAA_FAULTS = {
    "msaa_pattern_mirrored": ("FAULT_MSAA_PATTERN_MIRRORED", "the picture drawn upside down "
                              "(clip y negated, front face swapped) and its rows read back "
                              "turned: the sample pattern mirrored top to bottom"),
    "msaa_depth_per_pixel": ("FAULT_MSAA_DEPTH_PER_PIXEL", "gl_FragDepth = gl_FragCoord.z: "
                             "one depth per fragment, tested and stored at every sample (the "
                             "depth test per pixel instead of per sample)"),
    "msaa_srgb_resolve": ("FAULT_MSAA_SRGB_RESOLVE", "the colour resolved in sRGB space "
                          "(decoded, averaged, encoded) instead of by the linear box filter"),
    "msaa_centre_coverage": ("FAULT_MSAA_CENTRE_COVERAGE", "GL_MULTISAMPLE disabled: coverage "
                             "taken at the pixel centre only, the fragment written to every "
                             "sample"),
}
FAULTS.update(MSAA_FAULTS)

#: Planted faults of the technique scenes at samples > 1 (issue 44;
#: :mod:`refraster.gl.msaa_techniques`, tests/test_golden_msaa_techniques.py), also in
#: :data:`FAULTS`.
MSAA_TECHNIQUE_FAULTS = {
    "msaa_edges_resolved_for_per_sample": ("FAULT_MSAA_EDGES_RESOLVED", "the edge operators "
                                           "read sample 0 at every sample: the edge map of "
                                           "the resolved G-buffer where per-sample is "
                                           "declared"),
    "msaa_gbuffer_pixel_rate": ("FAULT_MSAA_GBUFFER_PIXEL_RATE", "the multisampled G-buffers "
                                "drawn without sample shading: one invocation per pixel, its "
                                "inputs at the pixel centre, where sample-rate interpolation "
                                "is declared"),
    "msaa_divide_at_centre": ("FAULT_MSAA_DIVIDE_AT_CENTRE", "the sample-rate inputs (the clip "
                              "program's, the multisampled technique G-buffers') left to "
                              "llvmpipe's own perspective divide: a/w at the sample divided by "
                              "the pixel centre's 1/w"),
}
FAULTS.update(MSAA_TECHNIQUE_FAULTS)
