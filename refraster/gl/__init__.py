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

__all__ = ["SUPPORTED_TECHNIQUES", "FAULTS", "TECHNIQUE_FAULTS", "CONVENTION_FAULTS"]

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
