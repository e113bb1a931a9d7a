"""``python -m labutils.carve PAR_FILE --out MODEL.ply [--grid N] [--masks DIR]``: space carving from the command line.

Reads a Middlebury camera file (the images beside it), learns the background's colours from the image borders,
makes one silhouette per image, finds the object's box, carves the visual hull on a voxel grid, and writes its
surface (marching cubes) as a binary PLY mesh; with ``--masks DIR`` also the silhouettes as PNGs
(``<image>_mask.png``). Progress goes to stderr. Every failure is one line on stderr,
``error: <file>[, line N]: what is wrong``, with exit status 2, and nothing is written; an output that is the
camera file, an image or another output is refused before any work. A model whose silhouettes match the masks
poorly (median IoU < 0.5) is still written (exit 0), with one ``carve: warning: ...`` line on stderr; so is one
whose silhouettes match some views' masks less well than IoU 0.9: one ``carve: warning: unsure silhouettes in ...``
line naming them.

The estimators live in :mod:`labutils.model.carving`; this module is the thin command line around them.
"""
import os
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from ...core import cli as _cli
from ...data.middlebury import read_par
from ...data.ply import write_mesh
from . import (
    VoxelGrid,
    background_model,
    bounding_box_from_silhouettes,
    carve,
    clean_mask,
    colour_distance,
    segment_views,
    silhouette_ious,
    surface_mesh,
    unsure_warning,
)

DEFAULT_GRID = 128
MIN_MEDIAN_IOU = 0.5          # below it the written model is reported with a warning on stderr


def _log(quiet, *parts):
    if not quiet:
        print(*parts, file=sys.stderr, flush=True)


def _read_images(views):
    images = []
    for path in views.image_paths:
        img = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if img is None:
            raise _cli.CommandError(f"{path}: cannot read the image (not an image file, or damaged)")
        images.append(cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
    return images


def _temporary(folder, name):
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{name}.", suffix=".tmp")
    os.close(fd)
    return tmp


def _finish(tmp):
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)


def run(args):
    """Do the work of :func:`main`; raise :class:`labutils.core.cli.CommandError`/``ValueError``/``OSError`` on
    failure."""
    t_start = time.perf_counter()
    par = Path(args.par)
    out = Path(args.out)
    if par.is_dir():
        raise _cli.CommandError(f"{par}: is a folder; give the camera file (e.g. {par / (par.name + '_par.txt')})")
    if not par.is_file():
        raise _cli.CommandError(f"{par}: no such file")
    _cli.check_distinct([(out, "--out")], [(par, "the input PAR_FILE")])
    _cli.check_output_path(out, "--out")
    out_dir = out.parent if str(out.parent) else Path(".")
    masks_dir = Path(args.masks) if args.masks else None
    if masks_dir is not None and not masks_dir.is_dir():
        raise _cli.CommandError(f"{masks_dir}: the masks folder does not exist")
    if masks_dir is not None and not os.access(masks_dir, os.W_OK):
        raise _cli.CommandError(f"{masks_dir}: the masks folder is not writable")
    if args.grid < 8 or args.grid > 512:
        raise _cli.CommandError(f"--grid must be between 8 and 512 voxels; got {args.grid}")
    if args.threshold == "auto":
        args.threshold = None
    else:
        try:
            args.threshold = float(args.threshold)
        except ValueError:
            raise _cli.CommandError(f"--threshold must be a number or 'auto'; got {args.threshold!r}") from None
        if not args.threshold >= 0:
            raise _cli.CommandError(f"--threshold must be a number >= 0 or 'auto'; got {args.threshold!r}")

    views = read_par(par)
    masks_out = [(masks_dir / f"{Path(p).stem}_mask.png", "a --masks file") for p in views.image_paths] \
        if masks_dir is not None else []
    _cli.check_distinct([(out, "--out")] + masks_out,
                        [(par, "the input PAR_FILE")] + [(p, "an input image") for p in views.image_paths])
    _log(args.quiet, f"carve: {views.n_views} cameras from {par}; reading the images")
    images = _read_images(views)
    for i, img in enumerate(images):
        if img.shape[0] <= 8 or img.shape[1] <= 8:
            raise _cli.CommandError(f"{views.image_paths[i]}: the image is too small ({img.shape[1]}x{img.shape[0]})")

    try:
        vertices, faces, normals, masks, ious, grid, threshold = _compute(args, views, images, par)
    except ValueError as exc:
        raise _cli.CommandError(f"{par}: {exc}") from None
    _write(args, out, out_dir, masks_dir, views, masks, vertices, faces, normals, grid, threshold, par)
    seconds = time.perf_counter() - t_start
    print(f"wrote {out} ({len(vertices)} vertices, {len(faces)} triangles; silhouette IoU min {ious.min():.3f}, "
          f"median {np.median(ious):.3f})" + (f" and {len(masks)} masks in {masks_dir}" if masks_dir else "")
          + f" in {seconds:.1f} s")
    median = float(np.median(ious))
    if median < MIN_MEDIAN_IOU:             # written, but the model does not explain the masks: say so
        print(f"carve: warning: the model's silhouettes hardly match the masks (median IoU {median:.3f} < "
              f"{MIN_MEDIAN_IOU}): object and background colours too close, or wrong cameras; look at --masks",
              file=sys.stderr, flush=True)
    else:
        unsure = unsure_warning(ious, [Path(p).name for p in views.image_paths])
        if unsure:                          # some views' masks and the others contradict each other
            print(f"carve: warning: {unsure}; look at --masks", file=sys.stderr, flush=True)
    return 0


def _compute(args, views, images, par):
    P = views.P
    t0 = time.perf_counter()
    threshold = args.threshold
    if threshold is None:
        seg = segment_views(images, P, every=3, check=False)     # the finer model below is checked
        table = ", ".join(f"{c:.3g}: {med:.3f}/{lo:.3f}"
                          for c, (med, lo) in zip(seg.candidates, seg.scores) if med >= 0)
        threshold, masks = seg.threshold, seg.masks
        _log(args.quiet, f"carve: background of {seg.model.n_clusters} colour clusters from the image borders; "
                         f"colour threshold {threshold:.3g} (silhouette agreement on a coarse grid, median/min IoU: "
                         f"{table}) [{time.perf_counter() - t0:.1f} s]")
    else:
        model = background_model(images)
        masks = [clean_mask(colour_distance(img, model) > threshold) for img in images]
    empty = [str(views.image_paths[i]) for i, m in enumerate(masks) if not m.any()]
    if empty:
        raise _cli.CommandError(f"{empty[0]}: the silhouette is empty (no pixel differs from the background's "
                                f"colours by more than {threshold:g}): is the object in the image?")

    t0 = time.perf_counter()
    box = bounding_box_from_silhouettes(masks, P)
    grid = VoxelGrid.from_box(box, args.grid)
    _log(args.quiet, f"carve: box {np.round(box[0], 4).tolist()} .. {np.round(box[1], 4).tolist()}; grid "
                     f"{' x '.join(map(str, grid.shape))} = {grid.n_voxels:,} voxels of {grid.voxel_size:.3g}")

    def progress(v, alive):
        if (v + 1) % 10 == 0 or v + 1 == views.n_views:
            _log(args.quiet, f"carve: view {v + 1}/{views.n_views}, {alive:,} voxels still near or inside")

    carving = carve(masks, P, grid, progress=progress)
    if carving.n_occupied == 0:
        raise _cli.CommandError(f"{par}: every voxel was carved away: the masks and the cameras disagree (check that "
                         "P = K [R | t] maps the object into each image, and look at the masks with --masks)")
    vertices, faces, normals = surface_mesh(carving)
    ious = silhouette_ious(vertices, faces, masks, P)
    _log(args.quiet, f"carve: {carving.n_occupied:,} voxels occupied, surface {len(vertices):,} vertices and "
                     f"{len(faces):,} triangles [{time.perf_counter() - t0:.1f} s]; IoU of its silhouettes with "
                     f"the masks: min {ious.min():.3f} (view {int(np.argmin(ious))}), median {np.median(ious):.3f}")
    return vertices, faces, normals, masks, ious, grid, threshold


def _write(args, out, out_dir, masks_dir, views, masks, vertices, faces, normals, grid, threshold, par):
    """Write everything to temporary files first, then rename them all: nothing is left half-written."""
    temps = []
    try:
        tmp = _temporary(out_dir, out.name)
        temps.append((tmp, out))
        write_mesh(tmp, vertices, faces, normals=normals, format="ascii" if args.ascii else "binary_little_endian",
                   comments=[f"visual hull of {par.name} by labutils.carve: grid {grid.shape}, voxel "
                             f"{grid.voxel_size:.6g}, colour threshold {threshold:.6g}"])
        if masks_dir is not None:
            for path, m in zip(views.image_paths, masks):
                name = f"{Path(path).stem}_mask.png"
                tmp = _temporary(masks_dir, name)
                temps.append((tmp, masks_dir / name))
                ok, buf = cv2.imencode(".png", m.astype(np.uint8) * 255)
                if not ok:
                    raise _cli.CommandError(f"{masks_dir / name}: cannot encode the mask as PNG")
                with open(tmp, "wb") as f:
                    f.write(buf.tobytes())
        for tmp, _ in temps:
            _finish(tmp)
        for tmp, dst in temps:
            os.replace(tmp, dst)
    except BaseException:
        for tmp, _ in temps:
            if os.path.exists(tmp):
                os.remove(tmp)
        raise


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (0, or 2 after one ``error: ...`` line on stderr)."""
    parser = _cli.Parser(
        prog="python -m labutils.carve",
        description="Space carving: the visual hull of an object seen by calibrated cameras (a Middlebury camera "
                    "file, images beside it), written as a PLY mesh.")
    parser.add_argument("par", metavar="PAR_FILE",
                        help="camera file: the image count, then per image 'name k11..k33 r11..r33 t1 t2 t3' "
                             "(P = K [R | t])")
    parser.add_argument("--out", required=True, metavar="MODEL.ply", help="the surface, a binary PLY mesh")
    parser.add_argument("--grid", type=int, default=DEFAULT_GRID, metavar="N",
                        help=f"voxels along the longest side of the object's box (default {DEFAULT_GRID})")
    parser.add_argument("--masks", metavar="DIR", help="also write the silhouettes as DIR/<image>_mask.png")
    parser.add_argument("--threshold", default="auto",
                        help="colour distance (Mahalanobis, in CIELAB, to the nearest of the background's colour "
                             "clusters) above which a pixel is the object, or 'auto' to pick the one whose "
                             "silhouettes agree best (default auto)")
    parser.add_argument("--ascii", action="store_true", help="write an ASCII PLY instead of binary")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    args = parser.parse_args(argv)
    try:
        return run(args)
    except OSError as exc:
        if exc.filename:                      # an OSError from the system: name the file it was about
            raise OSError(f"{exc.filename}: {exc.strerror or exc}") from None
        raise
    except MemoryError:
        raise _cli.CommandError(f"{args.par}: out of memory: try a smaller --grid") from None


if __name__ == "__main__":
    sys.exit(_cli.run(main))
