"""refraster.wgpu: a WebGPU backend (WGSL) for refraster's golden scene packages (optional
extra ``wgpu``).

A WebGPU team's client of the goldens, written as one: WGSL files (``shaders/gbuffer.wgsl``; the
techniques' ``shaders/edges.wgsl``, ``shaders/clip.wgsl``, ``shaders/cutaway.wgsl`` and ``shaders/halos.wgsl`` with
:mod:`refraster.wgpu.edges`, :mod:`refraster.wgpu.clipsurface`, :mod:`refraster.wgpu.cutaway`
and :mod:`refraster.wgpu.halos`)
beside a thin driver (:mod:`refraster.wgpu.driver`) on wgpu-py
(wgpu-native), which on a machine without a GPU runs on Mesa's lavapipe (Vulkan on llvmpipe).
It reads only the scene
packages of a golden directory (``scene.json``, PLY meshes, ``.npy`` maps) through the
standalone package reader :mod:`refraster.gl.package` (standard library and NumPy), renders in
the convention each scene declares, and works under WebGPU's **default limits**
(:data:`refraster.wgpu.device.DEFAULT_LIMITS`: 32 bytes per sample across the colour targets,
so the G-buffer takes three passes), asking for an optional feature only by name
(:data:`refraster.wgpu.device.OPTIONAL_FEATURES`).

``import refraster`` never imports this subpackage; ``import refraster.wgpu`` imports no wgpu
either (the device is created by :class:`refraster.wgpu.driver.Backend`).

    from refraster.wgpu.driver import Backend
    with Backend() as gpu:
        buffers = gpu.render("golden/render_cube/package")   # {name: (H, W[, C]) array}

On the command line: ``refraster golden candidate GOLDEN_DIR --backend wgpu --out CANDIDATE_DIR``
(docs/backends.md, "refraster.wgpu").
"""

__all__ = ["SUPPORTED_TECHNIQUES", "LATER_TECHNIQUES", "FAULTS", "CONVENTION_FAULTS",
           "TECHNIQUE_FAULTS"]

#: Techniques this backend renders, with how.
SUPPORTED_TECHNIQUES = {
    "render": "the G-buffer in three passes of at most 32 bytes per sample (ids and depths; "
              "normal and barycentrics; colour), de-indexed draws with flat face attributes",
    "ldi": "classic depth peeling (one pass per layer, the previous layer read with "
           "textureLoad; front to back under less and lequal, and under greater and gequal)",
    "vds": "the volumetric parity test in the fragment shader over the sprite as a 2D array "
           "texture",
    # issue 45 (refraster/wgpu/edges.py, shaders/edges.wgsl)
    "edges": "the edge G-buffer T_G (rgba8unorm or rgba32float), the operators in one "
             "full-screen pass read with textureLoad, the width dilation, the Gooch NPR pass "
             "with the edge map composited (no optional feature)",
    # issue 45 (refraster/wgpu/clipsurface.py, shaders/clip.wgsl)
    "clipsurface": "2.5D clip surfaces: the clip test's discard with the offset map filtered "
                   "bilinearly in WGSL under the surface's address mode (no float32-filterable), "
                   "caps as the exported grid with the parity-test discard, shaded from the "
                   "derived and user maps; the G-buffer in three passes",
    # issue 45 (refraster/wgpu/cutaway.py, shaders/cutaway.wgsl)
    "cutaway": "rear hulls (greater), seeds, ping-pong jump flooding in full-screen render "
               "passes with the scene's schedule, D_dil and the cut normals, the clipped "
               "G-buffer in three passes with the cut flag, ghost lines as a line list whose "
               "opacity is kept as the maximum by a depth32float attachment (no optional "
               "feature)",
    # issue 45 (refraster/wgpu/halos.py, shaders/halos.wgsl)
    "halos4d": "per slicing plane a compute pass cutting every tetrahedron into a storage "
               "buffer drawn as the vertex buffer (no geometry shader), Eq. 3's halo depth "
               "kept as the per-pixel minimum by a depth32float attachment, the surface "
               "fragment by a depth-tested key, the resolve composited into ping-pong "
               "rgba32float textures read with textureLoad (no optional feature)",
}

#: Techniques skipped with a reason as not implemented yet (none: issue 45 is done).
LATER_TECHNIQUES = ()

#: Planted faults of the technique passes (issue 45; tests/test_wgpu_techniques.py), test-only
#: like :data:`FAULTS`, kept apart so that the G-buffer's matrix (tests/test_wgpu_backend.py)
#: stays its own: name → (where, what it does).
TECHNIQUE_FAULTS = {
    "sobel_transposed": ("edges.wgsl: the SOBEL_TRANSPOSED constant",
                         "the Sobel G_y kernel written as the transposed G_x (edges along x "
                         "vanish)"),
    "one_diagonal": ("edges.wgsl: the ONE_DIAGONAL constant",
                     "the diagonal normal and depth operators with one diagonal (A–H) only"),
    "offset_wrong_address_mode": ("clip.wgsl: the WRONG_ADDRESS_MODE constant",
                                  "the offset map sampled clamp-to-edge where the surface says "
                                  "repeat or mirrored repeat (and repeat where it says "
                                  "clamp-to-edge)"),
    "parity_far_end": ("clip.wgsl: the PARITY_FAR_END constant",
                       "the caps' parity count started at the sprite's far end (the last "
                       "layer) with the front-to-back early exit"),
    "jfa_halved_once_more": ("host: refraster.wgpu.cutaway.schedule",
                             "the jump-flooding schedule with n halved once too often: its "
                             "first jump n/4 instead of n/2"),
    "ghost_not_depth_tested": ("cutaway.wgsl: the GHOST_NOT_DEPTH_TESTED constant",
                               "the ghost lines not depth-tested against the removed layer "
                               "(z < D): only against the visible objects of interest"),
    "ndc_y_from_row": ("cutaway.wgsl: the NDC_Y_FROM_ROW constant",
                       "the full-screen passes' NDC y taken from the framebuffer row as "
                       "OpenGL's gl_FragCoord.y (row 0 at the bottom): the floor constraint "
                       "and the cut normals' unprojection upside down"),
    "plane_half_slab": ("halos.wgsl: the PLANE_HALF_SLAB constant",
                        "the slicing plane's depth offset by half a slab: z = c_k + dz/2, "
                        "the slab's far boundary instead of its centre"),
    "halo_depth_max": ("host: the halo-depth pipeline's depthCompare",
                       "the halo depth kept as the per-pixel maximum (greater, cleared to 0) "
                       "instead of the minimum: the depth trick that replaces MIN blending "
                       "turned around"),
}

#: Planted faults (tests only; ``Backend(faults=[name, ...])``): name → (where, what it does).
FAULTS = {
    "gl_remap_on_zero_to_one": ("host: the DEPTH_REMAP constant",
                                "OpenGL's depth remap z' = (z + w)/2 applied to a scene whose "
                                "projection is already [0, 1] (depth_range zero_to_one)"),
    "y_not_flipped": ("host: the Y_SIGN constant",
                      "y not flipped between NDC and the image: NDC y = +1 lands on the "
                      "image's bottom row"),
    "reversed_z_less": ("host: the pipeline's depthCompare",
                        "a reversed-Z scene (greater) drawn with the depth test less"),
    "clear_one_under_greater": ("host: the depth attachment's depthClearValue",
                                "the depth buffer cleared to 1 under the depth test greater"),
    "half_pixel": ("gbuffer.wgsl: the HALF_PIXEL constant",
                   "the viewport shifted by half a pixel in x and y (vertex stage)"),
    "provoking_vertex_face_id": ("host: the face attribute",
                                 "the face id as a per-vertex attribute of an indexed mesh "
                                 "(the last face listing the vertex), read flat from the "
                                 "provoking vertex"),
    "sprite_rows_flipped": ("gbuffer.wgsl: the SPRITE_ROWS_FLIPPED constant",
                            "the volumetric depth sprite's rows read top-down"),
}

#: Planted faults of the API conventions (issue 39; tests/test_wgpu_conventions.py), also in
#: :data:`FAULTS`, beside the three of :data:`FAULTS` that concern the conventions too
#: (``gl_remap_on_zero_to_one``, ``reversed_z_less``, ``clear_one_under_greater``).
CONVENTION_FAULTS = {
    "winding_not_flipped": ("host: the read-back and primitive.frontFace",
                            "Vulkan's NDC y down (ndc_y 'down') drawn without the clip-y "
                            "negation and mirrored top to bottom at read-back, frontFace left "
                            "as the scene says although the framebuffer is mirrored: front "
                            "and back swap"),
    "unclipped_depth_dropped": ("host: the pipeline's primitive state",
                                "depth clamp (raster.depth_clamp) drawn without "
                                "unclippedDepth — wgpu-py 0.32's own behaviour without "
                                "refraster.wgpu.device.unclipped_depth: near/far clipping "
                                "kept"),
    "depth_not_quantised": ("host: the depth read-back",
                            "under the unorm depth formats, the float32 @builtin(position).z "
                            "written as the candidate's depth instead of the depth buffer "
                            "(k / (2^n − 1))"),
}
FAULTS.update(CONVENTION_FAULTS)
