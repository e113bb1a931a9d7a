"""The data: where it lives, how to fetch it, how to load it, and the files the command lines read and write.

Modules: :mod:`~labutils.data.paths` (the data path, and the message when a set is missing),
:mod:`~labutils.data.registry` (every file of every set, pinned by size and sha256),
:mod:`~labutils.data.fetch` (``python -m labutils.data fetch|list``), :mod:`~labutils.data.loaders` (the
dinosaur, the fountain, the temple, and the synthetic fallback), :mod:`~labutils.data.formats` (track,
calibration and result files), :mod:`~labutils.data.bal` (BAL problems), :mod:`~labutils.data.middlebury`
(Middlebury camera files) and :mod:`~labutils.data.ply` (PLY point clouds and meshes).
"""
from .bal import BALProblem, read_bal, write_bal
from .formats import read_calibration, read_result_json, read_tracks, write_tracks
from .loaders import TEMPLE_BOX, load_dino, load_fountain, load_scene, load_temple
from .middlebury import read_par
from .paths import DataNotFoundError, data_dirs, find_data, has_data
from .ply import read_model, read_ply, validate_ply, write_mesh, write_ply, write_points

__all__ = ["BALProblem", "read_bal", "write_bal", "read_calibration", "read_result_json", "read_tracks",
           "write_tracks", "TEMPLE_BOX", "load_dino", "load_fountain", "load_scene", "load_temple", "read_par",
           "DataNotFoundError", "data_dirs", "find_data", "has_data", "read_model", "read_ply", "validate_ply",
           "write_mesh", "write_ply", "write_points"]
