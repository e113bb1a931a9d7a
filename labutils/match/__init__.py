"""Correspondences from images: features, matching, epipolar filtering, tracks and the choice of pairs.

The pipeline, one function per step:

1. **Detect and describe** (:func:`detect_features`): OpenCV's SIFT (Lowe, IJCV 2004) on a grey image,
   optionally reduced first (:func:`read_gray`); the pixels of a reduced image map back to the original
   with :func:`to_original_pixels`, and K follows with :func:`scale_calibration`.
2. **Nearest neighbours** (:func:`nearest_neighbours`): the two closest descriptors in the other image, by
   brute force (a matrix product, in chunks).
3. **Ratio test** (:func:`ratio_test`, Lowe 2004 Sec. 7.1): keep a match only if its nearest neighbour is
   clearly closer than the second nearest, ``d1 < ratio · d2``.
4. **Mutual (cross) check** (:func:`mutual_check`): keep ``i -> j`` only if ``i`` is also the nearest
   neighbour of ``j`` in the first image.
5. **Epipolar filter** (:func:`epipolar_filter`): a robust F from our RANSAC
   (:func:`labutils.twoview.fundamental_ransac`, Sampson distance, H&Z Alg. 11.4); with known K, E and
   the relative pose are refined on the inliers (5 parameters instead of 7, H&Z Sec. 9.6) and matches
   whose 3D point would lie behind a camera are rejected too (cheirality).
6. **Tracks** (:func:`build_tracks`): pairwise matches chained across views with union-find; a track
   that holds two different features of one view is contradictory and is rejected.
   :func:`verify_tracks` also checks each track against the epipolar geometry of every pair of its views,
   including the pairs it only reaches through a third view.
7. **Which pairs** (:func:`select_pairs`, :func:`retrieval_pairs`): all pairs for a few views, neighbours in
   a sequence or on a ring, or a shortlist from a bag of visual words.

:func:`match_views` runs steps 2-5 over a list of pairs and keeps a table of the survivors of each
stage; :func:`tracks_from_matches` runs step 6. ``python -m labutils.match`` (:mod:`labutils.match.cli`) runs
everything on a folder of images.

Pixel convention: OpenCV puts pixel centres at integer coordinates, so reducing an image by ``s`` maps
a pixel ``x`` of the original to ``s (x + 0.5) - 0.5``, not to ``s x`` (half a pixel apart).
"""
from .cli import main
from .descriptors import (
           DescriptorMatches,
           Features,
           detect_features,
           match_descriptors,
           mutual_check,
           nearest_neighbours,
           ratio_test,
)
from .geometric import PairGeometry, epipolar_filter
from .images import IMAGE_SUFFIXES, read_gray, resize_gray, scale_calibration, to_original_pixels, to_working_pixels
from .pairs import retrieval_pairs, select_pairs
from .pipeline import MatchResult, TrackResult, match_views, tracks_from_matches
from .synthetic import blob_texture, render_corner
from .tracks import UnionFind, build_tracks, track_pixels, track_statistics, verify_tracks

__all__ = ["Features", "read_gray", "resize_gray", "scale_calibration", "to_original_pixels", "to_working_pixels",
           "DescriptorMatches", "detect_features", "nearest_neighbours", "ratio_test", "mutual_check",
           "match_descriptors",
           "PairGeometry", "epipolar_filter", "UnionFind", "build_tracks",
           "track_pixels", "verify_tracks", "select_pairs", "retrieval_pairs", "MatchResult", "match_views",
           "TrackResult", "tracks_from_matches", "track_statistics", "IMAGE_SUFFIXES", "blob_texture", "render_corner",
           "main"]
