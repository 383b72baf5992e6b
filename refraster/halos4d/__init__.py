"""Volumetric halos for surfaces in 4D (Wang, Yan, Fu, Hanson, Heng, EuroVis 2013).

Stages, one module each: :mod:`.surfaces` (uv-sampled 4D surfaces with tangents),
:mod:`.transforms` (rotations in six planes, 4D → 3D projection with 4D depth),
:mod:`.thicken` (view-dependent thickening, prisms → tetrahedra, Eq. 3),
:mod:`.slicing` (cross-sections and voxelization), :mod:`.render` (the frame), whose options
are the values of :mod:`.options` (:class:`View4D`, :class:`Halos`, :class:`HaloStyle`). See
``docs/halos4d.md`` and MATH.md §5.
"""

from .options import STEREO_ANGLE, HaloStyle, Halos, View4D
from .render import (HaloGeometry, HaloRender, prepare, render_halos, render_halos_pair,
                     slice_alpha)
from .slicing import SliceTriangles, slice_tetrahedra, voxel_centres, voxelize
from .surfaces import (Surface4D, calabi_yau_quartic, colored_by_depth, fermat_surface,
                       figure1_scene, merge,
                       product_polynomial, quadratic_fermat, spun_trefoil, twist_spun_trefoil,
                       uv_surface)
from .thicken import (default_halo_parameters, halo_depth, prism_tetrahedra, thicken,
                      thickening_normals)
from .transforms import PLANES, Projection, compose, hanson_view, project, rotate_3d, rotation

__all__ = [
    "HaloGeometry", "HaloRender", "prepare", "render_halos", "render_halos_pair", "slice_alpha",
    "View4D", "Halos", "HaloStyle", "STEREO_ANGLE",
    "SliceTriangles", "slice_tetrahedra", "voxel_centres", "voxelize",
    "Surface4D", "calabi_yau_quartic", "colored_by_depth", "fermat_surface", "figure1_scene",
    "merge",
    "product_polynomial", "quadratic_fermat", "spun_trefoil", "twist_spun_trefoil", "uv_surface",
    "default_halo_parameters", "halo_depth", "prism_tetrahedra", "thicken", "thickening_normals",
    "PLANES", "Projection", "compose", "hanson_view", "project", "rotate_3d", "rotation",
]
