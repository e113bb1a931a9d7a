"""Dense stereo from known cameras: rectify a pair, sweep disparities with a ZNCC cost, check left against right,
turn disparities into depth and 3D points, and fuse the depth maps of several pairs into one coloured cloud.

1. **Rectification** (:func:`rectify_pair`): Fusiello's homographies from the known cameras
   (:mod:`labutils.calibrate.rectification`), at full or reduced size; matches then lie on the same row, ``x2 = x1 -
   d``.
2. **Disparity** (:func:`disparity_plane_sweep`): a plane sweep over the disparity range the object's box spans
   (:func:`disparity_range`), scored by the zero-mean normalised cross-correlation of square windows
   (:func:`zncc`, :func:`zncc_volume`; box filters from integral images, :func:`box_mean`), winner takes all,
   refined to sub-pixel by a parabola. OpenCV's ``StereoSGBM`` is the reference beside it, in the notebook.
3. **Left–right check** (:func:`left_right_check`): sweep again from the right image; keep a pixel only if its
   match maps back to it. Occlusions and most mismatches fail.
4. **Depth and points** (:func:`depth_from_disparity`, :func:`depth_map_from_disparity`, :class:`DepthMap`):
   ``Z = f b / d`` and back-projection; :func:`stereo_depth_map` does steps 2–4 for one pair.
5. **Fusion** (:func:`fuse_depth_maps`): keep the points other depth maps confirm (:func:`depth_agreement`), merge
   duplicates on a grid (:func:`merge_points`); :func:`ring_pairs` chooses the pairs of a ring of views.
6. **A synthetic pair with exact disparities** (:func:`make_layered_pair`) for the tests; the textured spheres
   with exact depth are :func:`labutils.model.make_textured_spheres`.

References: Szeliski, *Computer Vision: Algorithms and Applications*, 2nd ed., ch. 12; Scharstein & Szeliski, "A
taxonomy and evaluation of dense two-frame stereo correspondence algorithms", IJCV 2002; H&Z Sec. 11.12.
"""
from .depth import (
    DepthMap,
    RectifiedPair,
    depth_from_disparity,
    depth_map_from_disparity,
    disparity_range,
    rectify_pair,
    ring_pairs,
    scale_intrinsics,
    stereo_depth_map,
)
from .disparity import as_grey, box_mean, disparity_plane_sweep, left_right_check, zncc, zncc_volume
from .fusion import FusedCloud, depth_agreement, depth_in_map, fuse_depth_maps, merge_points
from .synthetic import LayeredPair, make_layered_pair

__all__ = ["as_grey", "box_mean", "zncc", "zncc_volume", "disparity_plane_sweep", "left_right_check",
           "RectifiedPair", "rectify_pair", "scale_intrinsics", "disparity_range", "depth_from_disparity", "DepthMap",
           "depth_map_from_disparity", "stereo_depth_map", "ring_pairs", "FusedCloud", "depth_in_map",
           "depth_agreement", "merge_points", "fuse_depth_maps", "LayeredPair", "make_layered_pair"]
