"""``python -m labutils.match IMAGE_DIR K.txt --out TRACKS.txt [--max-size PIXELS] [--seed N]``.

Tracks from a folder of calibrated images: the images (PNG, JPEG) in sorted file-name order, K as
``python -m labutils.sfm`` reads it (one shared 3×3, or one per image stacked), and a VGG track file
out (one row per track, ``x y`` per image in that order, ``-1 -1`` where unseen), in the pixels of the
original images, ready for ``python -m labutils.sfm TRACKS.txt K.txt --out RESULT.json``.

The work is :mod:`labutils.match`; this module only reads, reports and writes. Progress (a bar per
stage) goes to stderr; every failure is one line on stderr, ``error: <file>[, line N]: what is wrong``,
with exit status 2, and nothing is written; an ``--out`` that is K or one of the images is refused before any work.
"""
import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from ..core import cli as _cli
from ..data.formats import read_calibration, write_tracks
from .descriptors import detect_features
from .images import IMAGE_SUFFIXES, read_gray, scale_calibration, to_original_pixels
from .pairs import select_pairs
from .pipeline import match_views, tracks_from_matches
from .tracks import track_statistics


def image_files(folder: str | Path) -> list[Path]:
    """The PNG and JPEG files of ``folder`` in sorted file-name order."""
    return sorted(p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


def run(args: argparse.Namespace, log: Callable[[str], None]) -> int:
    """Do the work of :func:`main` for parsed ``args``; ``log`` prints a line to stderr. Returns the track count."""
    folder = Path(args.image_dir)
    if not folder.is_dir():
        raise _cli.CommandError(f"{folder}: not a folder")
    _cli.check_distinct([(args.out, "--out")], [(args.K, "the input K file")]
                        + [(p, "an input image") for p in image_files(folder)])
    if args.max_size is not None and args.max_size < 16:
        raise _cli.CommandError(f"--max-size must be at least 16 pixels; got {args.max_size}")
    if args.window is not None and args.window < 1:
        raise _cli.CommandError(f"--window must be at least 1; got {args.window}")
    if not 0 < args.ratio <= 1:
        raise _cli.CommandError(f"--ratio must be in (0, 1]; got {args.ratio}")
    if not args.threshold > 0:
        raise _cli.CommandError(f"--threshold must be positive; got {args.threshold}")
    paths = image_files(folder)
    if len(paths) < 2:
        raise _cli.CommandError(f"{folder}: {len(paths)} image{'s' if len(paths) != 1 else ''} (PNG, JPEG); at least 2 "
                                "are needed")
    try:
        K = read_calibration(args.K, len(paths))
    except ValueError as exc:
        raise _cli.CommandError(str(exc).replace("views of the tracks file", f"images in {folder}")) from None
    _cli.check_output_path(args.out, "--out")
    for p in paths:                      # a format check from each file's first bytes, before any work
        if not cv2.haveImageReader(str(p)):
            raise _cli.CommandError(f"{p}: cannot read the image (not a PNG/JPEG file, or damaged)")
    V = len(paths)
    log(f"{V} images in {folder}" + (f", reduced to at most {args.max_size} px" if args.max_size else ""))

    bar = _cli.Progress(V, "features", quiet=args.quiet)
    features = []
    for p in paths:
        try:
            gray, scale, _ = read_gray(p, args.max_size)
        except ValueError as exc:
            if not args.quiet:
                sys.stderr.write("\n")
            raise _cli.CommandError(str(exc)) from None
        features.append(detect_features(gray, scale=scale))
        bar.step()
    K_work = np.stack([scale_calibration(K[v], f.scale) for v, f in enumerate(features)])

    strategy = args.pairs
    if strategy == "auto":
        strategy = "all" if V <= 20 else "sequence"
    window = args.window if args.window is not None else 5
    pairs = select_pairs(V, strategy, window if strategy != "all" else None)
    log(f"{sum(len(f) for f in features)} features ({min(len(f) for f in features)}-{max(len(f) for f in features)} "
        f"per image); matching {len(pairs)} pairs ({strategy}" + ("" if strategy == "all" else f", window {window}")
        + ")")
    bar = _cli.Progress(len(pairs), "matching", quiet=args.quiet)
    result = match_views(features, pairs, rng=np.random.default_rng(args.seed), K=K_work, ratio=args.ratio,
                         threshold_px=args.threshold, min_inliers=args.min_inliers,
                         progress=lambda done, total=None: bar.step(done - bar.n))
    tot = result.totals()
    log(f"matches: {tot['ratio']} after the ratio test, {tot['mutual']} mutual, {tot['epipolar']} epipolar inliers "
        f"in {len(result.matches)} of {len(pairs)} pairs "
        f"({result.seconds['matching']:.1f} s matching, {result.seconds['epipolar']:.1f} s epipolar filter)")
    tracks = tracks_from_matches(features, result)
    stats = track_statistics(tracks.x)
    log(f"tracks: {stats['tracks']} ({tracks.n_conflicts} rejected for two features in one image), "
        f"{stats['observations']} observations, length {2 if stats['tracks'] else 0}-{stats['max_length']}, "
        f"mean {stats['mean_length']:.2f}")
    if stats["tracks"] == 0:
        raise _cli.CommandError(f"{folder}: no tracks found (no pair of images has {args.min_inliers} verified "
                                "matches)")
    x = np.stack([to_original_pixels(tracks.x[v], f.scale) for v, f in enumerate(features)])
    write_tracks(args.out, x)
    return stats["tracks"]


def main(argv: list[str] | None = None) -> int:
    """The command line; returns the exit status (0, or 2 after a one-line error on stderr)."""
    parser = _cli.Parser(
        prog="python -m labutils.match",
        description="Tracks from a folder of calibrated images (SIFT, ratio test, mutual check, epipolar filter "
                    "with known K, union-find), written as a VGG track file for python -m labutils.sfm.")
    parser.add_argument("image_dir", help="folder of images (PNG, JPEG), used in sorted file-name order")
    parser.add_argument("K", help="calibration: one 3x3 matrix shared by all images, or one per image (3V rows)")
    parser.add_argument("--out", required=True, help="the track file to write: one row per track, 'x y' per image, "
                                                     "-1 -1 where unseen, in the pixels of the original images")
    parser.add_argument("--max-size", type=int, default=None,
                        help="reduce each image so that its longer side is at most this many pixels (default: none)")
    parser.add_argument("--seed", type=_cli.seed_arg, default=0,
                        help="seed of the random generator, a non-negative integer (default 0)")
    parser.add_argument("--pairs", choices=("auto", "all", "sequence", "ring"), default="auto",
                        help="which pairs to match (default auto: all for up to 20 images, else sequence)")
    parser.add_argument("--window", type=int, default=None,
                        help="for --pairs sequence/ring: match images at most this far apart (default 5)")
    parser.add_argument("--ratio", type=float, default=0.8, help="ratio-test threshold (default 0.8)")
    parser.add_argument("--threshold", type=float, default=1.0,
                        help="epipolar (Sampson) threshold in pixels of the reduced images (default 1)")
    parser.add_argument("--min-inliers", type=int, default=20,
                        help="fewest verified matches to keep a pair (default 20)")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    args = parser.parse_args(argv)

    def log(msg):
        if not args.quiet:
            print(msg, file=sys.stderr, flush=True)

    n = run(args, log)
    print(f"wrote {args.out}: {n} tracks in {len(image_files(args.image_dir))} images")
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
