"""``python -m labutils.reconstruct PHOTOS_DIR --out RESULT.json [--K K.txt | --calibration CAL.json] [--ply MODEL.ply]
[--report REPORT.md] [--max-size PIXELS] [--seed N] [--quiet]``.

From a folder of photos of one object, taken with one camera, to its cameras and a coloured, oriented point cloud
(:func:`labutils.reconstruct.reconstruct_photos`). Without ``--K`` or ``--calibration`` the camera is estimated:
EXIF focal length or self-calibration, then one focal length and radial distortion ``(k1, k2)`` refined with the
cameras (the log gives the estimate and its standard deviation).

``RESULT.json``: ``{"images": [...], "cameras": [...], "points": [[x, y, z], ...], "colors": [[r, g, b], ...],
"focal": {...}, "capture": [...]}``, with one camera per image in sorted file-name order — ``{"R": 3×3, "t": 3,
"K": 3×3, "dist": [k1, k2]}`` in the workbook's convention (``x_cam = R @ X + t``, pixels of the original photos,
``x = K · distort(x_cam[:2] / x_cam[2])``) — or ``null`` for an image that did not register.

The capture check comes first, on stderr and in the report, within seconds of the matching; progress on stderr;
every failure one line (``error: ...``), exit status 2, nothing written. An output that is one of the photos,
the calibration or another output is refused before any work.
"""
import json
import sys
import time
from pathlib import Path

import numpy as np

from ..core import cli as _cli
from ..data.formats import read_calibration
from ..data.ply.write import write_points
from .pipeline import NotReconstructable, image_files, reconstruct_photos


def _check_outputs(args, photos):
    outs = [(args.out, "--out"), (args.ply, "--ply"), (args.report, "--report")]
    for path, flag in outs:
        if path:
            _cli.check_output_path(path, flag)
    _cli.check_distinct(outs, [(p, "a photo") for p in photos]
                        + [(args.K, "the --K file"), (args.calibration, "the --calibration file")])


def _camera(args, n):
    if args.K and args.calibration:
        raise _cli.CommandError("give --K or --calibration, not both")
    if args.K:
        return read_calibration(args.K, n)[0], None
    if args.calibration:
        try:
            cal = json.loads(Path(args.calibration).read_text())
            K, dist = np.asarray(cal["K"], float), np.asarray(cal.get("dist", [0, 0]), float)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise _cli.CommandError(f"{args.calibration}: not a calibration from python -m labutils.calibrate "
                                    f"({type(exc).__name__}: {exc})") from None
        if K.shape != (3, 3) or dist.ndim != 1 or not 2 <= dist.size <= 5:
            raise _cli.CommandError(f"{args.calibration}: K must be 3x3 and dist 2 to 5 numbers")
        if dist.size > 2 and np.any(dist[2:] != 0):
            print("reconstruct: warning: p1, p2, k3 of the calibration are not modelled (only k1, k2)",
                  file=sys.stderr)
        return K, dist[:2]
    return None, None


def _report(rec, seconds):
    lines = ["# Reconstruction report", "", "## Capture check", ""] + rec.capture.text()
    f = rec.focal
    sd = f" ± {f['sd']:.1f} (1 sd)" if f["sd"] else ""
    lines += ["", "## Camera", "", f"- focal length {f['value']:.1f} px{sd}"
              + f", source: {f['source']}, start {f['start']:.1f} px",
              f"- radial distortion k1 = {rec.dist[0]:.4f}, k2 = {rec.dist[1]:.4f}",
              "", "## Result", "", f"- {int(rec.registered.sum())} of {len(rec.names)} views registered, "
              f"{len(rec.X)} points, {seconds:.1f} s"]
    lines += [f"- view {v} ({rec.names[v]}) did not register" for v in np.flatnonzero(~rec.registered)]
    return "\n".join(lines) + "\n"


def main(argv=None):
    """The command line; returns the exit status (0, or 2 after a one-line error on stderr)."""
    parser = _cli.Parser(prog="python -m labutils.reconstruct",
                         description="Cameras and a coloured point cloud from a folder of photos of one object "
                                     "(one camera; calibrated or not).")
    parser.add_argument("photos_dir", help="folder of photos (JPEG, PNG), used in sorted file-name order")
    parser.add_argument("--out", required=True, help="RESULT.json to write")
    parser.add_argument("--K", help="calibration of the photos: a 3x3 K file (as python -m labutils.sfm reads)")
    parser.add_argument("--calibration", help="CALIB.json from python -m labutils.calibrate (K and distortion)")
    parser.add_argument("--ply", help="also write the points (colours, normals) as a binary PLY file")
    parser.add_argument("--report", help="also write a Markdown report: capture check, camera, result")
    parser.add_argument("--max-size", type=int, default=1200, help="working size: longer side in pixels "
                                                                   "(default 1200)")
    parser.add_argument("--seed", type=_cli.seed_arg, default=0, help="seed of the random generator (default 0)")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    args = parser.parse_args(argv)
    if args.max_size < 64:
        raise _cli.CommandError(f"--max-size must be at least 64 pixels; got {args.max_size}")
    folder = Path(args.photos_dir)
    if not folder.is_dir():
        raise _cli.CommandError(f"{folder}: not a folder")
    photos = image_files(folder)
    if len(photos) < 2:
        raise _cli.CommandError(f"{folder}: {len(photos)} photos (JPEG, PNG); at least 2 are needed")
    _check_outputs(args, photos)
    K, dist = _camera(args, len(photos))
    t0 = time.perf_counter()

    def log(msg):
        if not args.quiet:
            print(f"reconstruct [{time.perf_counter() - t0:5.1f} s]: {msg}", file=sys.stderr, flush=True)

    bars = {}

    def progress(stage, done, total):
        bar = bars.setdefault(stage, _cli.Progress(total, stage, quiet=args.quiet))
        bar.step(done - bar.n)

    try:
        rec = reconstruct_photos(photos, rng=np.random.default_rng(args.seed), K=K, dist=dist,
                                 max_size=args.max_size, log=log, progress=progress)
    except NotReconstructable as exc:
        raise _cli.CommandError(f"{folder}: cannot reconstruct: {exc}") from None
    seconds = time.perf_counter() - t0
    result = {"images": rec.names, "cameras": rec.cameras(), "points": np.round(rec.X, 9).tolist(),
              "colors": rec.colors.tolist(),
              "focal": {k: v if isinstance(v, str) else float(v) for k, v in rec.focal.items()},
              "capture": rec.capture.problems}
    outputs = {args.out: json.dumps(result, indent=1) + "\n"}
    if args.report:
        outputs[args.report] = _report(rec, seconds)
    if args.ply:                                   # written atomically; removed again if the others fail
        write_points(args.ply, rec.X, rec.colors, normals=rec.normals)
    try:
        _cli.write_all_atomically(outputs)
    except OSError:
        if args.ply:
            Path(args.ply).unlink(missing_ok=True)
        raise
    print(f"wrote {args.out}: {int(rec.registered.sum())} of {len(rec.names)} views, {len(rec.X)} points, "
          f"f = {rec.focal['value']:.1f} px")
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
