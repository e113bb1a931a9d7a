"""Space carving: silhouettes from colour, a voxel grid, carving by projection, the surface, and its overlap.

The visual hull (Laurentini 1994) is the largest shape whose projection into every view stays inside that view's
silhouette: the intersection of the silhouettes' back-projected cones. Carving it on a voxel grid (Szeliski 1993;
the dinosaur is Fitzgibbon, Cross & Zisserman's turntable sequence, SMILE 1998; Kutulakos & Seitz, "A theory of
shape by space carving", IJCV 2000, add photo-consistency) keeps a voxel when its centre projects inside every
silhouette. Here:

1. **Silhouettes from colour** (:func:`background_model`, :func:`colour_distance`, :func:`silhouette`,
   :func:`segment_views`): the background's colours are learnt from a thin frame at the image borders (the object
   does not touch it) as a few clusters in plain CIELAB (lightness counts like hue: a grey object on black is as
   visible as an orange one on blue; a background of two tones gets two clusters); a pixel belongs to the object
   when its Mahalanobis distance to every cluster exceeds a threshold taken from the data: the border's own
   distances give the lowest, and the views' agreement once carved picks among the candidates above it
   (:func:`choose_threshold`); small specks are removed and small holes filled. Views whose mask the carved model
   explains poorly are reported unsure (:func:`unsure_warning`).
2. **A voxel grid** (:class:`VoxelGrid`) over a box: given, or found from the silhouettes alone by carving coarse
   grids around the point the silhouettes' central rays meet (:func:`bounding_box_from_silhouettes`).
3. **Carving** (:func:`inside_silhouette` for one view, :func:`carve` for all): vectorised over voxels, one pass
   per view over the voxels still alive. Besides the occupancy it keeps, per voxel, the smallest signed distance
   to a silhouette boundary (pixels × depth / focal length: world units), positive inside: a field whose zero level
   is the hull's surface to a fraction of a pixel, and whose sign is the occupancy.
4. **The surface** by marching cubes from scikit-image (:func:`surface_mesh`), and its **silhouettes**
   (:func:`render_silhouette`) compared with the masks by their intersection over union (:func:`mask_iou`,
   :func:`silhouette_ious`).

Pixels: ``(x, y)`` with x right, y down; pixel ``mask[r, c]`` is centred on ``(c, r)`` (OpenCV), so a point at
``(x, y)`` falls in ``mask[floor(y + 0.5), floor(x + 0.5)]``. Cameras: ``P = K [R | t]`` (any scale or sign of P
is accepted: depth is taken as in H&Z Sec. 6.2.3).
"""
from .consensus import (
    MIN_AGREEMENT,
    Silhouettes,
    choose_threshold,
    segment_views,
    threshold_ladder,
    unsure_views,
    unsure_warning,
)
from .silhouettes import (
    QUANTISATION,
    BackgroundModel,
    background_model,
    clean_mask,
    colour_distance,
    mask_iou,
    signed_distance_map,
    silhouette,
)
from .surface import mesh_volume, render_silhouette, silhouette_ious, surface_mesh
from .voxels import Carving, VoxelGrid, bounding_box_from_silhouettes, carve, inside_silhouette, project_with_depth

__all__ = ["BackgroundModel", "background_model", "colour_distance", "silhouette", "clean_mask", "signed_distance_map",
           "mask_iou", "VoxelGrid", "Carving", "project_with_depth", "inside_silhouette", "carve",
           "bounding_box_from_silhouettes", "surface_mesh", "mesh_volume", "render_silhouette", "silhouette_ious",
           "QUANTISATION", "threshold_ladder", "choose_threshold", "Silhouettes", "segment_views", "MIN_AGREEMENT",
           "unsure_views", "unsure_warning"]
