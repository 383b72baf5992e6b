"""The catalogue of GPU bug classes (issue 41; ``docs/conformance.md``): for each class of
implementation bug, the fault of :data:`refraster.gl.FAULTS` that plants it in this backend (the
bug itself, in a shader ``#define`` or the driver's GL state and upload) and the built-in golden
scenes expected to catch it. ``tests/test_conformance_catalogue.py`` renders every class's
scenes with the correct backend (every scene must pass) and with its fault (every listed scene
must fail), and writes the table of ``docs/conformance.md`` (``docs/scripts/
conformance_table.py``).

Plain data: no import beyond the standard library (the import rule of refraster.gl).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["BugClass", "GROUPS", "CLASSES", "TECHNIQUE_SCENES", "by_name"]

#: The groups, in the order of docs/conformance.md.
GROUPS = ("transforms", "rasterization", "depth", "state", "data", "compositing",
          "technique-specific")

#: Scenes of the technique passes (their goldens take minutes to generate: the fast CI subset
#: of tests/test_conformance_catalogue.py leaves out the classes caught only there).
TECHNIQUE_SCENES = ("clipsurface_building", "edges_building", "edges_sobel", "cutaway_shells",
                    "cutaway_floor", "halos4d_figure1", "edges4gl_building_per_sample",
                    "cutaway4gl_shells_per_sample", "msaa4gl_clipsurface_sample")


@dataclass(frozen=True)
class BugClass:
    """One class of GPU implementation bug.

    ``name``: the class; ``group``: one of :data:`GROUPS`; ``fault``: its planted fault (a key
    of :data:`refraster.gl.FAULTS`); ``scenes``: the built-in scenes expected to catch it;
    ``bug``: the class in one sentence; ``allowance``: for a class the golden allows by design,
    what is allowed and which variant outside the allowance is planted (else empty)."""

    name: str
    group: str
    fault: str
    scenes: tuple
    bug: str
    allowance: str = ""


_C = BugClass
CLASSES = (
    # --- transforms -------------------------------------------------------------------------
    _C("normal matrix", "transforms", "normal_matrix_modelview", ("catalogue_transforms",),
       "normals transformed by the model-view matrix instead of its inverse transpose (wrong "
       "under a non-uniform scale only)"),
    _C("mirrored model matrix", "transforms", "mirror_compensated", ("catalogue_transforms",),
       "facing of a model matrix with a negative determinant: the golden judges facing by the "
       "window winding (GL's rule), a backend that flips glFrontFace for mirrored draws "
       "reports their outward faces as front"),
    _C("matrix layout", "transforms", "matrix_row_major", ("render_cube",
                                                           "catalogue_transforms"),
       "row-major matrices uploaded to GL's column-major uniforms without the transpose"),
    _C("projection handedness", "transforms", "projection_left_handed", ("render_cube",),
       "a projection for a left-handed eye space (looking down +z) applied to the package's "
       "right-handed one"),
    _C("perspective-correct interpolation", "transforms", "noperspective",
       ("render_cube",), "attributes interpolated linearly in window space"),
    _C("winding under an upper-left origin", "transforms", "winding_not_flipped",
       ("vulkan_cube",),
       "glFrontFace not inverted with the origin (GL negates the polygon area under "
       "GL_UPPER_LEFT): front and back swap"),
    # --- rasterization ----------------------------------------------------------------------
    _C("half-pixel offset", "rasterization", "half_pixel", ("render_cube",),
       "the viewport shifted by half a pixel (pixel centres at integers)"),
    _C("sub-pixel precision", "rasterization", "subpixel_1bit", ("render_cube",),
       "vertices snapped to too coarse a grid",
       "the sub-pixel bits the golden declares (4 to 8; 8 by default) are allowed (the coverage "
       "allowance moves every edge by the snapping of either); the planted variant snaps to 1 "
       "bit (a half-pixel grid)"),
    _C("fill rule on shared edges", "rasterization", "fill_rule_neither",
       ("catalogue_pixel_centres",),
       "a pixel centre exactly on an edge shared by two triangles covered by neither",
       "either fill rule (top-left or bottom-left; the centre goes to exactly one of the two "
       "triangles) is allowed; the planted variant gives it to neither (a crack)"),
    _C("huge triangles and the guard band", "rasterization", "guard_band_clamp",
       ("catalogue_huge_near",),
       "vertices past the guard band clamped to it instead of clipped"),
    _C("near-plane crossing (w -> 0)", "rasterization", "near_w_clamped",
       ("catalogue_huge_near",),
       "clip w clamped away from 0 instead of clipping at the near plane"),
    _C("degenerate triangles", "rasterization", "degenerate_dropped",
       ("catalogue_pixel_centres",),
       "zero-area triangles removed at upload, shifting the primitive ids after them"),
    _C("multisample pattern orientation", "rasterization", "msaa_pattern_mirrored",
       ("msaa4gl_cube",),
       "the sample pattern mirrored top to bottom (GL's y-up positions taken as the picture's, "
       "or a picture drawn upside down and turned): per-sample coverage at the wrong samples"),
    _C("multisample coverage", "rasterization", "msaa_centre_coverage", ("msaa4gl_cube",),
       "coverage taken at the pixel centre only and the fragment written to every sample "
       "(GL_MULTISAMPLE off)"),
    # --- depth ------------------------------------------------------------------------------
    _C("depth range remap", "depth", "depth_remap_on_zero_to_one",
       ("zero_to_one_near_crossing", "catalogue_depth_precision"),
       "a [0, 1] clip depth remapped as if it were GL's [-1, 1] (0.5 z/w + 0.5)"),
    _C("linear vs window depth", "depth", "linear_depth_written", ("render_cube",),
       "the linear eye depth written where the window depth is expected"),
    _C("depth format and precision", "depth", "depth_unorm16_declared_float",
       ("catalogue_depth_precision",),
       "a 16-bit fixed-point depth buffer where the scene declares float32",
       "under GL's [-1, 1] clip depth a window depth within 4e-5 is allowed, which admits a "
       "16-bit buffer; under a [0, 1] clip depth the relative float32 model applies, and the "
       "depth-precision scene (near/far 1e-3/1e4) catches the planted 16-bit buffer there"),
    _C("depth clamp", "depth", "depth_clamp_always", ("catalogue_huge_near",),
       "GL_DEPTH_CLAMP enabled where the scene clips at the near plane"),
    _C("reversed-Z depth test", "depth", "reversed_z_less", ("reversed_z_multi_draw",),
       "reversed-Z drawn with the depth test 'less'"),
    _C("per-sample depth", "depth", "msaa_depth_per_pixel", ("msaa4gl_cube",),
       "one depth per fragment (the pixel centre's) tested and stored at every sample instead "
       "of the depth plane at each sample"),
    # --- state ------------------------------------------------------------------------------
    _C("cull mode", "state", "cull_face_inverted",
       ("render_nested_shells", "render_icosphere_smooth"),
       "glCullFace front and back swapped"),
    _C("front face", "state", "front_face_inverted", ("render_cube",),
       "glFrontFace CCW and CW swapped"),
    _C("facing in the shader", "state", "facing_flipped", ("render_cube",),
       "gl_FrontFacing read inverted"),
    _C("depth function", "state", "depth_func_always", ("render_multi_draw",),
       "the depth function left at GL_ALWAYS (the last fragment drawn wins)"),
    _C("clear values", "state", "reversed_z_clear_one", ("reversed_z_multi_draw",),
       "the depth buffer cleared to 1 under a 'greater' depth test"),
    _C("draw order across draw calls", "state", "depth_cleared_per_draw",
       ("render_multi_draw",),
       "the depth buffer cleared before each draw call, so a later draw covers an earlier "
       "nearer one"),
    # --- data -------------------------------------------------------------------------------
    _C("base vertex", "data", "base_vertex_ignored", ("render_multi_draw",),
       "draws packed into one vertex buffer with their indices used without the base vertex"),
    _C("index offset", "data", "index_offset", ("render_cube",),
       "the index range of a draw read one index late"),
    _C("16-bit indices", "data", "index16", ("catalogue_many_vertices",),
       "indices uploaded as 16-bit, truncated past 65,535 vertices"),
    _C("object ids across draws", "data", "object_id_stale", ("render_multi_draw",),
       "the per-draw object id set once per frame"),
    _C("read-back row order", "data", "readback_rows_unflipped", ("render_cube",),
       "GL's bottom-first rows kept as if row 0 were the top"),
    # --- compositing ------------------------------------------------------------------------
    _C("sRGB encode", "compositing", "srgb_encoded", ("render_cube",),
       "the linear colour sRGB-encoded into a linear float target"),
    _C("premultiplied vs straight alpha", "compositing", "halo_premultiplied",
       ("halos4d_figure1",),
       "straight-alpha slices blended as premultiplied (ONE, ONE_MINUS_SRC_ALPHA)"),
    _C("slice compositing order", "compositing", "slices_front_to_back",
       ("halos4d_figure1",), "back-to-front slices composited front to back"),
    _C("multisample resolve space", "compositing", "msaa_srgb_resolve", ("msaa4gl_cube",),
       "the colour samples resolved in sRGB space (decoded, averaged, encoded) instead of by "
       "the linear box filter"),
    # --- technique-specific -----------------------------------------------------------------
    _C("depth peeling discard", "technique-specific", "peel_no_discard",
       ("ldi_nested_shells",), "the previous layer not discarded"),
    _C("parity counted from the wrong end", "technique-specific", "parity_wrong_end",
       ("vds_parity_building",),
       "the parity count run from the back layer with the front-to-back early exit"),
    _C("sprite row order", "technique-specific", "sprite_rows_flipped",
       ("vds_parity_building",), "the volumetric depth sprite's rows read top-down"),
    _C("clip test sign", "technique-specific", "clip_sign_flipped", ("clipsurface_building",),
       "the clip surface's test with its sign flipped"),
    _C("offset-map axes", "technique-specific", "offset_t_flipped", ("clipsurface_building",),
       "the offset map's t axis flipped"),
    _C("offset-map filtering", "technique-specific", "offset_map_nearest",
       ("clipsurface_building",), "the offset map sampled NEAREST instead of bilinearly"),
    _C("offset-map wrap", "technique-specific", "offset_map_clamped",
       ("clipsurface_building",), "the offset map clamped to its edge whatever its wrap"),
    _C("caps parity", "technique-specific", "cap_no_parity", ("clipsurface_building",),
       "caps drawn without the parity-test discard"),
    _C("JFA step schedule", "technique-specific", "schedule_truncated", ("cutaway_shells",),
       "the jump-flooding schedule without its last passes"),
    _C("cutaway slope", "technique-specific", "slope_from_theta", ("cutaway_shells",),
       "the cutaway slope from tan θ instead of cot θ"),
    _C("floor constraint", "technique-specific", "floor_flipped", ("cutaway_floor",),
       "the floor constraint's normal with its sign flipped"),
    _C("ghost lines depth test", "technique-specific", "ghost_not_depth_tested",
       ("cutaway_shells",),
       "ghost-line fragments not tested against the removed layer D"),
    _C("edge operator diagonals", "technique-specific", "one_diagonal", ("edges_building",),
       "the diagonal normal and depth operators with one diagonal only"),
    _C("Sobel kernel orientation", "technique-specific", "sobel_transposed", ("edges_sobel",),
       "the Sobel G_y kernel written transposed"),
    _C("Eq. 3's sign", "technique-specific", "eq3_sign", ("halos4d_figure1",),
       "Eq. 3's halo drop-off subtracted (the halo in front of the line)"),
    _C("Eq. 3's drop-off", "technique-specific", "eq3_halved", ("halos4d_figure1",),
       "Eq. 3's drop-off δd halved"),
    _C("image pass on the resolved G-buffer", "technique-specific",
       "msaa_edges_resolved_for_per_sample", ("edges4gl_building_per_sample",),
       "the edge map computed once on the resolved G-buffer (sample 0's) and written for every "
       "sample where the scene declares the filters per sample"),
    _C("interpolation rate of a multisampled G-buffer", "technique-specific",
       "msaa_gbuffer_pixel_rate", ("edges4gl_building_per_sample",
                                   "cutaway4gl_shells_per_sample"),
       "the multisampled G-buffer drawn without sample shading (one invocation per pixel, its "
       "inputs at the pixel centre) where the scene declares sample-rate interpolation"),
    _C("perspective divide at sample rate", "technique-specific", "msaa_divide_at_centre",
       ("msaa4gl_clipsurface_sample",),
       "a sample-rate input's a/w evaluated at the sample but divided by the pixel centre's 1/w "
       "(Mesa 22.3.6 llvmpipe's own smooth interpolation under sample shading): the clip and "
       "parity tests at a point off the sample"),
)


def by_name():
    """``{class name: BugClass}``."""
    return {c.name: c for c in CLASSES}
