"""The house rules of every command line, checked on each (issues 8 and 14): ``--help`` exits 0; every failure is
one line on stderr naming the file (and line), exit status 2, never a traceback; the output folder is checked before
the work; output is written atomically with the usual mode, and nothing is left behind on failure (also when the
disk is full); no RuntimeWarning; progress on stderr and a clean stdout."""
import json
import os
import signal
import subprocess
import sys
import time
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


# ------------------------------------------------------------------------------------------------- outputs vs inputs
def _snapshot(folder):
    return {p.relative_to(folder).as_posix(): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(Path(folder).rglob("*")) if p.is_file()}


@pytest.fixture
def inputs(tracks_and_K, bal_problem):
    """One folder with an input of each command: tracks, K, a BAL problem, a camera file, a folder of images."""
    d = tracks_and_K
    os.replace(bal_problem, d / "p.txt")
    (d / "par.txt").write_text("1\nimg.png 1 0 0 0 1 0 0 0 1 1 0 0 0 1 0 0 0 1 0 0 5\n")
    (d / "img.png").write_bytes(b"not really an image")
    (d / "imgs").mkdir()
    for name in ("a.png", "b.png"):
        (d / "imgs" / name).write_bytes(b"not really an image")
    os.symlink("tracks.txt", d / "link.txt")
    os.link(d / "K.txt", d / "K-hard.txt")
    return d


@pytest.mark.parametrize("module, args, named", [
    ("sfm", ["tracks.txt", "K.txt", "--out", "tracks.txt"], "tracks.txt: --out is the input TRACKS file"),
    ("sfm", ["tracks.txt", "K.txt", "--out", "./K.txt"], "./K.txt: --out is the input K file"),
    ("sfm", ["link.txt", "K.txt", "--out", "tracks.txt"], "tracks.txt: --out is the input TRACKS file (link.txt)"),
    ("sfm", ["tracks.txt", "K-hard.txt", "--out", "r.json", "--ply", "K.txt"], "K.txt: --ply is the input K file"),
    ("sfm", ["tracks.txt", "K.txt", "--out", "r.json", "--ply", "r.json"], "r.json: --ply and --out name the same"),
    ("sfm", ["tracks.txt", "K.txt", "--out", "r.json", "--ply", "imgs/a.png", "--images", "imgs"],
     "imgs/a.png: --ply is an input image"),
    ("bundle", ["p.txt", "--out", "p.txt"], "p.txt: --out is the input PROBLEM file"),
    ("carve", ["par.txt", "--out", "par.txt"], "par.txt: --out is the input PAR_FILE"),
    ("carve", ["par.txt", "--out", "img.png"], "img.png: --out is an input image"),
    ("carve", ["par.txt", "--out", "imgs/img_mask.png", "--masks", "imgs"], "a --masks file and --out name the same"),
    ("match", ["imgs", "K.txt", "--out", "K.txt"], "K.txt: --out is the input K file"),
    ("match", ["imgs", "K.txt", "--out", "imgs/b.png"], "imgs/b.png: --out is an input image"),
])
def test_an_output_that_is_an_input_or_another_output_is_refused_before_any_work(inputs, module, args, named):
    """Issue 21: these overwrote their input and exited 0. Now: one line naming the file, exit 2, nothing touched."""
    before = _snapshot(inputs)
    proc = run(module, *args, cwd=inputs, timeout=60)
    one_line_error(proc, named)
    assert _snapshot(inputs) == before          # inputs untouched, nothing written, no temporary file


@pytest.mark.parametrize("module, args", [
    ("sfm", ["tracks.txt", "K.txt", "--out", "r.json", "--seed", "-1"]),
    ("match", ["imgs", "K.txt", "--out", "t.txt", "--seed", "x"]),
])
def test_a_bad_seed_blames_the_seed(inputs, module, args):
    before = _snapshot(inputs)
    one_line_error(run(module, *args, cwd=inputs, timeout=60), "--seed: must be a non-negative integer")
    assert _snapshot(inputs) == before


def test_check_distinct_compares_files_not_spellings(tmp_path):
    (tmp_path / "a.txt").write_text("a")
    os.symlink(tmp_path / "a.txt", tmp_path / "s.txt")
    _cli.check_distinct([(tmp_path / "new.txt", "--out"), (tmp_path / "b.txt", "--ply")], [(tmp_path / "a.txt", "x")])
    for out, inp in [("s.txt", "a.txt"), ("a.txt", "s.txt"), ("sub/../a.txt", "a.txt")]:
        (tmp_path / "sub").mkdir(exist_ok=True)
        with pytest.raises(_cli.CommandError, match=f"^{tmp_path / out}: --out is the input"):
            _cli.check_distinct([(tmp_path / out, "--out")], [(tmp_path / inp, "the input")])
    with pytest.raises(_cli.CommandError, match="--b and --a name the same file"):
        _cli.check_distinct([(tmp_path / "n.txt", "--a"), (tmp_path / "sub" / ".." / "n.txt", "--b")])


# ------------------------------------------------------------------------------------------------- BAL values, cost
@pytest.mark.parametrize("value", ["1e300", "inf", "nan", "-2e12"])
def test_bundle_refuses_absurd_values_at_read_time(bal_problem, tmp_path, value):
    lines = bal_problem.read_text().splitlines()
    lines[3] = " ".join(lines[3].split()[:2] + [value, lines[3].split()[3]])     # the 3rd observation's x
    bal_problem.write_text("\n".join(lines) + "\n")
    one_line_error(run("bundle", bal_problem, "--out", tmp_path / "o.txt", timeout=60), "problem.txt", "line 4",
                   repr(value))
    assert not (tmp_path / "o.txt").exists()


@pytest.mark.parametrize("solver", ["lm-schur", "scipy"])
@pytest.mark.parametrize("depth", ["zero", "tiny"])
def test_bundle_never_writes_a_solve_whose_cost_is_not_finite(bal_problem, tmp_path, depth, solver):
    """A point at depth 0 in a camera projects to infinity; at the smallest depth above 0, with f, k1, k2 = 1e12
    (values the reader accepts), its pixel is finite but its square overflows: either way an error on one line (no
    RuntimeWarning), never a written 'solution'."""
    from labutils.data.bal import read_bal

    p = read_bal(bal_problem)
    p.camera_params[0, :3] = 0.0                                          # camera 0: R = I exactly
    j = p.point_indices[p.camera_indices == 0][0]
    tz = p.camera_params[0, 5]
    if depth == "zero":
        p.points_3d[j] = [1.0, 1.0, -tz]                                  # depth exactly 0 in camera 0
    else:
        p.camera_params[0, 6:] = 1e12
        p.points_3d[j] = [1e12, 1e12, np.nextafter(-tz, 0.0)]
    write_bal(bal_problem, p)
    proc = run("bundle", bal_problem, "--out", tmp_path / "o.txt", "--solver", solver, timeout=120)
    one_line_error(proc, "problem.txt")
    assert sorted(q.name for q in tmp_path.iterdir()) == ["problem.txt"]


# ------------------------------------------------------------------------------------------------- Ctrl-C
def test_ctrl_c_while_the_command_loads_is_one_line_and_exit_130(tracks_and_K):
    """Sent while numpy is being imported (its shared library appears in the process's memory map): no traceback."""
    maps = Path("/proc/self/maps")
    if not maps.exists():
        pytest.skip("needs /proc to see when the command is importing numpy")
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-m", "labutils.sfm", "tracks.txt", "K.txt", "--out", "r.json"],
                            cwd=tracks_and_K, env=env, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            if "numpy" in Path(f"/proc/{proc.pid}/maps").read_text():
                break
        except OSError:
            pass
        time.sleep(0.002)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert (proc.returncode, err) == (_cli.INTERRUPTED, "error: interrupted\n"), (proc.returncode, err)
    assert sorted(p.name for p in tracks_and_K.iterdir()) == ["K.txt", "tracks.txt"]


def test_ctrl_c_while_running_is_one_line_and_leaves_no_temporary_file(tmp_path, monkeypatch, capsys):
    def interrupted(fd):
        raise KeyboardInterrupt
    monkeypatch.setattr(os, "fsync", interrupted)

    def main(argv):
        _cli.write_all_atomically({tmp_path / "a.txt": "a", tmp_path / "b.txt": "b"})

    assert _cli.run(main) == 130
    assert capsys.readouterr().err == "error: interrupted\n" and list(tmp_path.iterdir()) == []


def test_bench_keep_refuses_two_notebooks_of_one_name(tmp_path):
    for d in ("n1", "n2", "keep"):
        (tmp_path / d).mkdir()
    for d in ("n1", "n2"):
        (tmp_path / d / "x.ipynb").write_text("{}")
    one_line_error(run("bench", "notebooks", "n1/x.ipynb", "n2/x.ipynb", "--keep", "keep", cwd=tmp_path, timeout=60),
                   "keep/x.ipynb: --keep (for n2/x.ipynb) and --keep (for n1/x.ipynb) name the same file")
    assert list((tmp_path / "keep").iterdir()) == []
