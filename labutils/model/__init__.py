"""The 3D model (notebooks 10–12): coloured, oriented points, Delaunay meshes and their texture, the visual hull by
space carving, and dense stereo from known cameras.

Modules: :mod:`~labutils.model.pointcloud` (colours from the images, PCA normals oriented by visibility),
:mod:`~labutils.model.meshing` (Delaunay meshes carved through long edges), :mod:`~labutils.model.texturing`
(vertex colours from the most frontal unoccluded view), :mod:`~labutils.model.synthetic` (the synthetic
object with exact truth), :mod:`~labutils.model.carving` (silhouettes, voxel carving, marching cubes;
``python -m labutils.carve``) and :mod:`~labutils.model.stereo` (rectified pairs, plane-sweep ZNCC, the left–right
check, depth maps and their fusion).
"""
from .carving import (
    MIN_AGREEMENT,
    BackgroundModel,
    Carving,
    Silhouettes,
    VoxelGrid,
    background_model,
    bounding_box_from_silhouettes,
    carve,
    choose_threshold,
    clean_mask,
    colour_distance,
    inside_silhouette,
    mask_iou,
    mesh_volume,
    project_with_depth,
    render_silhouette,
    segment_views,
    signed_distance_map,
    silhouette,
    silhouette_ious,
    surface_mesh,
    threshold_ladder,
)
from .meshing import DelaunayMesh, boundary_faces, delaunay_mesh, face_normals, vertex_normals
from .pointcloud import (
    LocalPCA,
    PointCloud,
    cloud_from_reconstruction,
    estimate_normals,
    facing_fractions,
    local_pca,
    orient_normals,
    oriented_point_cloud,
    point_colors,
    sample_image,
)
from .stereo import (
    DepthMap,
    FusedCloud,
    LayeredPair,
    RectifiedPair,
    box_mean,
    depth_agreement,
    depth_from_disparity,
    depth_in_map,
    depth_map_from_disparity,
    disparity_plane_sweep,
    disparity_range,
    fuse_depth_maps,
    left_right_check,
    make_layered_pair,
    merge_points,
    rectify_pair,
    ring_pairs,
    scale_intrinsics,
    stereo_depth_map,
    zncc,
    zncc_volume,
)
from .synthetic import SphereScene, make_snowman, make_textured_scene, make_textured_spheres
from .texturing import (
    VertexTexture,
    VertexViews,
    edge_contrast,
    held_out_error,
    most_frontal_view,
    render_depth,
    texture_vertices,
    vertex_views,
)

__all__ = ["MIN_AGREEMENT", "Silhouettes", "segment_views", "threshold_ladder", "BackgroundModel", "Carving",
           "VoxelGrid", "background_model",
           "bounding_box_from_silhouettes", "carve", "choose_threshold", "clean_mask", "colour_distance",
           "inside_silhouette", "make_snowman", "mask_iou", "mesh_volume", "project_with_depth", "render_silhouette",
           "signed_distance_map", "silhouette", "silhouette_ious", "surface_mesh", "DelaunayMesh", "boundary_faces",
           "delaunay_mesh", "face_normals", "vertex_normals", "LocalPCA", "PointCloud", "cloud_from_reconstruction",
           "estimate_normals", "facing_fractions", "local_pca", "orient_normals", "oriented_point_cloud",
           "point_colors", "sample_image", "DepthMap", "FusedCloud", "LayeredPair", "RectifiedPair",
           "box_mean", "depth_agreement", "depth_from_disparity", "depth_in_map", "depth_map_from_disparity",
           "disparity_plane_sweep", "disparity_range", "fuse_depth_maps", "left_right_check", "make_layered_pair",
           "make_textured_spheres", "merge_points", "rectify_pair", "ring_pairs", "scale_intrinsics",
           "stereo_depth_map", "zncc", "zncc_volume", "SphereScene", "make_textured_scene", "VertexTexture",
           "VertexViews", "edge_contrast", "held_out_error", "most_frontal_view", "render_depth", "texture_vertices",
           "vertex_views"]
