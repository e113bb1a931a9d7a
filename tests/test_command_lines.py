"""The house rules of every command line, checked on each (issues 8 and 14): ``--help`` exits 0; every failure is
one line on stderr naming the file (and line), exit status 2, never a traceback; the output folder is checked before
the work; output is written atomically with the usual mode, and nothing is left behind on failure (also when the
disk is full); no RuntimeWarning; progress on stderr and a clean stdout."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from labutils.core import cli as _cli
from labutils.core.synthetic import make_scene
from labutils.data.bal import BALProblem, write_bal
from labutils.data.formats import write_tracks

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = ["sfm", "bundle", "bench", "data", "calibrate", "carve", "match", "tools.notebook_filter", "exercises"]


def run(module, *args, cwd=None, timeout=300):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-W", "error::RuntimeWarning", "-m", f"labutils.{module}", *map(str, args)],
                          capture_output=True, text=True, env=env, cwd=cwd or ROOT, timeout=timeout)


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def one_line_error(proc, *words):
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in proc.stderr, proc.stderr
    for w in words:
        assert w in lines[0], (w, lines[0])


@pytest.mark.parametrize("module", COMMANDS)
def test_help_exits_0_without_warnings(module):
    proc = run(module, "--help")
    assert proc.returncode == 0 and proc.stdout.startswith("usage: python -m labutils.") and proc.stderr == "", \
        proc.stderr


@pytest.mark.parametrize("module", ["sfm", "bundle", "calibrate"])
def test_bad_arguments_are_one_line(module):
    one_line_error(run(module, "--no-such-option"), "(see --help)")


# ------------------------------------------------------------------------------------------------- bundle
@pytest.fixture
def bal_problem(tmp_path):
    s = make_scene(30, 3, noise_px=0.5, rng=np.random.default_rng(0))
    D = np.diag([1.0, -1.0, -1.0])                     # our camera (z forward) -> BAL's (looks down -z, y up)
    from labutils.bundle.reprojection import camera_params_from_Rt
    from labutils.core.scene import observations

    cp = camera_params_from_Rt(D @ s.R, s.t @ D)
    ci, pi, x = observations(s.x_meas)
    u = (x - s.K[:2, 2]) / s.K[0, 0]
    bal = BALProblem(np.hstack([cp, np.tile([s.K[0, 0], 0.0, 0.0], (3, 1))]), s.X, ci, pi,
                     s.K[0, 0] * u * [1, -1])
    path = tmp_path / "problem.txt"
    write_bal(path, bal)
    return path


def test_bundle_writes_0644_and_json_is_one_document(bal_problem, tmp_path):
    out = tmp_path / "solved.txt"
    proc = run("bundle", bal_problem, "--out", out, "--json", "--verbose")
    assert proc.returncode == 0, proc.stderr
    json.loads(proc.stdout)                                    # the --verbose lines went to stderr
    assert "cost" in proc.stderr and "iter" in proc.stderr     # a per-iteration line, the way Ceres reports
    assert oct(out.stat().st_mode & 0o777) == oct(0o666 & ~_umask())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["problem.txt", "solved.txt"]


def test_bundle_refuses_a_folder_or_missing_folder_before_solving(bal_problem, tmp_path):
    (tmp_path / "adir").mkdir()
    one_line_error(run("bundle", bal_problem, "--out", tmp_path / "adir"), "adir", "is a folder")
    one_line_error(run("bundle", bal_problem, "--out", tmp_path / "nope" / "o.txt"), "nope", "does not exist")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir", "problem.txt"]
    assert list((tmp_path / "adir").iterdir()) == []


@pytest.mark.parametrize("text, words", [
    ("1 1 1\n0 " + "9" * 30 + " 1 2\n" + "0\n" * 12, ["bad.txt", "line 2", "too large"]),
    ("1 2 1\n0 0 1 2\n0 1 3 4\n" + "0\n" * 15, ["bad.txt", "line 1", "header says 1 observations"]),
])
def test_bundle_malformed_files_name_file_and_line(tmp_path, text, words):
    (tmp_path / "bad.txt").write_text(text)
    one_line_error(run("bundle", tmp_path / "bad.txt", "--out", tmp_path / "o.txt"), *words)
    assert not (tmp_path / "o.txt").exists()


def test_bundle_corrupt_bz2_names_the_file(tmp_path):
    (tmp_path / "p.txt.bz2").write_bytes(b"BZh9 this is not bzip2")
    one_line_error(run("bundle", tmp_path / "p.txt.bz2", "--out", tmp_path / "o.txt"), "p.txt.bz2", "bzip2")


def test_a_write_failure_leaves_nothing_behind(tmp_path, monkeypatch):
    """Disk full (or file too large): the temporary file is removed and the error names the path."""
    def full(fd):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError, match="out.txt: cannot write .No space left"):
        _cli.write_all_atomically({tmp_path / "out.txt": "x" * 1000, tmp_path / "other.txt": b"y"})
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------------------------- sfm
@pytest.fixture
def tracks_and_K(tmp_path):
    s = make_scene(150, 8, layout="turntable", noise_px=0.3, rng=np.random.default_rng(2))
    write_tracks(tmp_path / "tracks.txt", s.tracks)
    (tmp_path / "K.txt").write_text("\n".join(" ".join(repr(float(v)) for v in row) for row in s.K) + "\n")
    return tmp_path


def test_sfm_summary_once_progress_on_stderr_and_modes(tracks_and_K):
    d = tracks_and_K
    proc = run("sfm", "tracks.txt", "K.txt", "--out", "r.json", "--ply", "p.ply", cwd=d)
    assert proc.returncode == 0, proc.stderr
    summary = [line for line in (proc.stdout + proc.stderr).splitlines() if "views registered" in line]
    assert len(summary) == 1 and summary[0] in proc.stdout, proc.stdout   # the summary once, on stdout
    assert "initial pair" in proc.stderr                        # the progress log on stderr
    for f in ("r.json", "p.ply"):
        assert oct((d / f).stat().st_mode & 0o777) == oct(0o666 & ~_umask())
    assert sorted(p.name for p in d.iterdir()) == ["K.txt", "p.ply", "r.json", "tracks.txt"]


def test_sfm_existing_folder_as_out(tracks_and_K):
    d = tracks_and_K
    (d / "adir").mkdir()
    one_line_error(run("sfm", "tracks.txt", "K.txt", "--out", "adir", cwd=d), "adir", "is a folder")
    assert list((d / "adir").iterdir()) == [] and not list(d.glob(".*tmp"))


# ------------------------------------------------------------------------------------------------- bench
def test_bench_help_and_bad_subcommand():
    proc = run("bench", "ba", "--help")
    assert proc.returncode == 0 and "--quick" in proc.stdout
    one_line_error(run("bench", "nothing"), "nothing")
