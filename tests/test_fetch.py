"""The data registry and ``python -m labutils.data fetch/list``, tested for real without the internet.

A local HTTP server (``http.server`` in a thread, on 127.0.0.1) serves the real data folder found on the data path;
``$LABUTILS_DATA_URL`` points the fetcher at it, ``$LABUTILS_DATA`` at a temporary folder. Archives (the Middlebury
zip, the BAL ``.bz2``) are built from the same files and served beside it, so every kind of source is exercised.
"""
import bz2
import functools
import hashlib
import http.server
import os
import re
import shutil
import socket
import stat
import subprocess
import sys
import threading
import time
import zipfile
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import pytest

from labutils.data import fetch as F
from labutils.data import registry as D
from labutils.data.paths import COURSE_ONLY, data_dirs

NAMES = ["dino", "fountain-P11", "templeRing", "chessboard", "bal"]
PROJECT = Path(__file__).resolve().parents[1]


def _complete_sets():
    """{name: folder} for each set some folder on the data path holds completely (every file, at its size)."""
    found = {}
    for ds in F.DATASETS.values():
        for d in data_dirs():
            if all((d / ds.name / f.path).is_file() and (d / ds.name / f.path).stat().st_size == f.size
                   for f in ds.files):
                found[ds.name] = d / ds.name
                break
    return found


AVAILABLE = _complete_sets()        # CI, for one, has every set but the dinosaur (it has no public download)


def needs(*names):
    missing = [n for n in names if n not in AVAILABLE]
    return pytest.mark.skipif(bool(missing), reason=f"real data missing: {', '.join(missing)} not on the data path")


def sha256(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def files_under(folder):
    """Every file (and leftover temporary file) under ``folder``, as '/'-separated relative paths."""
    return sorted(p.relative_to(folder).as_posix() for p in Path(folder).rglob("*") if p.is_file())


def expected_mode():
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


# --- the server ------------------------------------------------------------------------------------------------
class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass

    def do_GET(self):
        self.server.hits.append(self.path)
        super().do_GET()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """Serves ``/good/<set>`` (the real sets found on the data path), ``/bad/chessboard`` (one byte of left01.jpg
    changed) and ``/archives`` (templeRing packed as Middlebury packs it, a copy with README.txt changed, the BAL
    file as .bz2)."""
    if not AVAILABLE:
        pytest.skip("real data missing: no data set is on the data path")
    root = tmp_path_factory.mktemp("www")
    (root / "good").mkdir()
    for name, folder in AVAILABLE.items():
        (root / "good" / name).symlink_to(folder, target_is_directory=True)
    if "chessboard" in AVAILABLE:
        bad = root / "bad" / "chessboard"
        bad.mkdir(parents=True)
        for f in F.DATASETS["chessboard"].files:
            (bad / f.path).symlink_to(AVAILABLE["chessboard"] / f.path)
        data = bytearray((AVAILABLE["chessboard"] / "left01.jpg").read_bytes())
        data[len(data) // 2] ^= 0xFF
        (bad / "left01.jpg").unlink()
        (bad / "left01.jpg").write_bytes(bytes(data))
    arch = root / "archives"
    arch.mkdir()
    if "templeRing" in AVAILABLE:
        for zname, broken in (("templeRing.zip", None), ("templeRing-bad.zip", "README.txt")):
            with zipfile.ZipFile(arch / zname, "w", zipfile.ZIP_STORED) as z:
                for f in F.DATASETS["templeRing"].files:
                    content = (AVAILABLE["templeRing"] / f.path).read_bytes()
                    z.writestr("templeRing/" + f.path, content + (b" " if f.path == broken else b""))
    if "bal" in AVAILABLE:
        bal = F.DATASETS["bal"].files[0].path
        (arch / (bal + ".bz2")).write_bytes(bz2.compress((AVAILABLE["bal"] / bal).read_bytes(), 1))

    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_QuietHandler, directory=str(root)))
    httpd.hits = []
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield SimpleNamespace(url=f"http://127.0.0.1:{httpd.server_address[1]}", hits=httpd.hits)
    httpd.shutdown()
    httpd.server_close()
    thread.join()


def closed_port_url():
    with socket.socket() as s:                      # bound, then closed: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    return f"http://127.0.0.1:{port}"


# --- the command line ------------------------------------------------------------------------------------------
def run_cli(*args, data, url=None, module="labutils.data"):
    env = {**os.environ, "LABUTILS_DATA": str(data), "PYTHONPATH": str(PROJECT)}
    env.pop(F.URL_ENV, None)
    if url is not None:
        env[F.URL_ENV] = url
    return subprocess.run([sys.executable, "-m", module, *args], capture_output=True, text=True, env=env,
                          timeout=300)


# runpy prints this warning when `python -m labutils.data` finds the module imported already (it did while the command
# was a module that labutils/__init__.py imported; test_data_entry_point_has_no_runpy_warning holds that it no longer
# is). The error-line checks look past it.
RUNPY_WARNING = re.compile(r"^<frozen runpy>:\d+: RuntimeWarning: 'labutils\.data' found in sys\.modules")


def error_lines(proc):
    return [line for line in proc.stderr.splitlines() if not RUNPY_WARNING.match(line)
            and not line.startswith(tuple(f"{n}: fetching" for n in NAMES))]


@pytest.fixture(scope="module")
def fetched(server, tmp_path_factory):
    """``python -m labutils.data fetch all`` (or every set found, when some are missing) from the local server
    into an empty folder, once."""
    data = tmp_path_factory.mktemp("data")
    names = ["all"] if set(AVAILABLE) == set(NAMES) else [n for n in NAMES if n in AVAILABLE]
    t0 = time.perf_counter()
    proc = run_cli("fetch", *names, "--force", data=data, url=server.url + "/good")   # the sets are on the data path
    print(f"\nfetch {' '.join(names)} over loopback: {time.perf_counter() - t0:.1f} s")
    return SimpleNamespace(proc=proc, data=data, names=[n for n in NAMES if n in AVAILABLE])


# --- the registry ----------------------------------------------------------------------------------------------
def test_registry_is_well_formed():
    assert list(F.DATASETS) == NAMES
    for name, ds in F.DATASETS.items():
        assert ds.name == name and ds.files and ds.licence and ds.citation and ds.origin
        paths = [f.path for f in ds.files]
        assert len(set(paths)) == len(paths), f"{name}: a path is listed twice"
        for f in ds.files:
            assert not f.path.startswith("/") and ".." not in f.path.split("/"), f.path
            assert re.fullmatch(r"[0-9a-f]{64}", f.sha256) and f.size > 0, f
        for s in ds.sources:
            assert s.kind in ("files", "bz2", "zip") and s.role in ("origin", "mirror"), s
            assert s.url.startswith("https://") and (s.kind != "zip" or s.member_prefix.endswith("/")), s
    assert not F.DATASETS["dino"].sources and "no public download" in F.DATASETS["dino"].note
    assert COURSE_ONLY == tuple(n for n, ds in F.DATASETS.items() if not ds.sources)    # what paths.how_to_get says
    assert all(ds.sources for ds in F.DATASETS.values() if ds.name != "dino")
    assert sum(ds.n_bytes for ds in F.DATASETS.values()) == 72_857_186      # the sets total ~73 MB


@pytest.mark.parametrize("name", NAMES)
def test_registry_covers_the_real_data_exactly(name):
    """Every file of the real copy is registered with its sha256, and nothing else is in it (but SOURCE.md)."""
    if name not in AVAILABLE:
        pytest.skip(f"real data missing: {name} not on the data path")
    ds, folder = F.DATASETS[name], AVAILABLE[name]
    assert [p for p in files_under(folder) if p != "SOURCE.md"] == sorted(f.path for f in ds.files)
    for f in ds.files:
        assert sha256(folder / f.path) == f.sha256, f"{name}/{f.path}"


def test_sources_follow_the_environment(monkeypatch):
    monkeypatch.setenv(F.URL_ENV, "http://example.org/mirror/")
    (src,) = F.sources_for("dino")
    assert src.url_of("images/viff.000.png") == "http://example.org/mirror/dino/images/viff.000.png"
    monkeypatch.setenv(F.URL_ENV, "  ")
    assert F.sources_for("bal") == F.DATASETS["bal"].sources


# --- fetching --------------------------------------------------------------------------------------------------
def test_cli_fetch_all_lays_out_every_set_verified(fetched):
    proc, data = fetched.proc, fetched.data
    assert proc.returncode == 0, proc.stderr
    assert error_lines(proc) == [], proc.stderr
    assert [line.split(":")[0] for line in proc.stdout.splitlines()] == fetched.names
    assert all("sha256 verified" in line for line in proc.stdout.splitlines())
    assert sorted(os.listdir(data)) == sorted(fetched.names)
    mode = expected_mode()
    for ds in (F.DATASETS[n] for n in fetched.names):
        assert files_under(data / ds.name) == sorted(f.path for f in ds.files), f"{ds.name}: stray or missing files"
        for f in ds.files:
            p = data / ds.name / f.path
            assert sha256(p) == f.sha256, f"{ds.name}/{f.path}"
            assert stat.S_IMODE(p.stat().st_mode) == mode, f"{p}: mode {oct(p.stat().st_mode)}"


def test_fetch_again_downloads_nothing_and_list_shows_present(fetched, server):
    before = len(server.hits)
    for name in fetched.names:
        rep = F.fetch(name, fetched.data, base_url=server.url + "/good", progress=False)
        assert rep.n_downloaded == 0 and rep.folder == fetched.data / name
    assert len(server.hits) == before
    proc = run_cli("list", data=fetched.data)
    assert proc.returncode == 0, proc.stderr
    rows = {line.split()[0]: line for line in proc.stdout.splitlines() if line.split()[:1] and line.split()[0] in NAMES}
    assert set(rows) == set(NAMES)
    for name in fetched.names:
        assert f"present in {fetched.data / name} (sha256 verified)" in rows[name]


@needs("chessboard")
def test_a_local_copy_that_fails_its_check_is_replaced(fetched, server, tmp_path):
    shutil.copytree(fetched.data / "chessboard", tmp_path / "chessboard")
    p = tmp_path / "chessboard" / "left02.jpg"
    p.write_bytes(p.read_bytes()[:-1] + b"x")
    (tmp_path / "chessboard" / "right03.jpg").unlink()
    st = F.status("chessboard", dirs=[tmp_path])
    assert (st.state, st.missing, st.corrupt) == ("incomplete", ["right03.jpg"], ["left02.jpg"])
    rep = F.fetch("chessboard", tmp_path, base_url=server.url + "/good", progress=False)
    assert rep.n_downloaded == 2 and F.status("chessboard", dirs=[tmp_path]).state == "present"


@needs("chessboard")
def test_a_corrupt_download_is_reported_by_name_and_removed(server, tmp_path):
    folder = tmp_path / "chessboard"
    folder.mkdir()
    (folder / "left01.jpg").write_bytes(b"an old, broken copy")      # must not survive either
    proc = run_cli("fetch", "chessboard", "--force", data=tmp_path, url=server.url + "/bad")
    assert proc.returncode == 2
    (line,) = error_lines(proc)
    assert line.startswith(f"error: {folder / 'left01.jpg'}: sha256 mismatch"), line
    assert "Traceback" not in proc.stderr
    assert files_under(folder) == ["calibration.yml"]               # fetched before it; no temporary files left
    assert sha256(folder / "calibration.yml") == F.DATASETS["chessboard"].files[0].sha256


def test_an_unreachable_server_is_one_error_and_leaves_nothing(tmp_path):
    with pytest.raises(F.FetchError) as exc:
        F.fetch("bal", tmp_path, base_url=closed_port_url(), progress=False)
    assert exc.value.path == tmp_path / "bal" / "problem-49-7776-pre.txt"
    assert "download from http://127.0.0.1:" in str(exc.value) and "\n" not in str(exc.value)
    assert str(exc.value).endswith(": 127.0.0.1 refused the connection") and not exc.value.unresolved
    assert list(tmp_path.iterdir()) == []                   # not even the empty folder bal/


def test_offline_one_line_per_set_says_offline_and_leaves_no_folder(tmp_path):
    """No host resolves (``.invalid`` never does): every set fails with the reason in a phrase and "offline?",
    exit status 2, and not even an empty folder stays behind."""
    proc = run_cli("fetch", "bal", "fountain-P11", "--force", data=tmp_path, url="http://nonexistent.invalid/")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and proc.stdout == ""
    lines = [line for line in error_lines(proc) if line.startswith("error: ")]
    assert [Path(line.split(": ")[1]).relative_to(tmp_path).parts[0] for line in lines] == ["bal", "fountain-P11"], \
        proc.stderr
    for line in lines:
        assert line.endswith("failed: cannot resolve the host nonexistent.invalid (offline? no host name resolved)")
    assert list(tmp_path.iterdir()) == []


@needs("chessboard")
def test_fetch_skips_a_set_present_and_verified_on_the_data_path(server, tmp_path, monkeypatch, capsys):
    """Issue 20: sets already verified on the data path were downloaded again. Now they are reported present and
    nothing is asked of the network; the others fail offline, one line per set, and leave no folder."""
    data = tmp_path / "data"
    shutil.copytree(AVAILABLE["chessboard"], data / "chessboard")
    monkeypatch.setattr(F, "data_dirs", lambda: [data])      # the data path: this folder only
    monkeypatch.setenv("LABUTILS_DATA", str(data))
    monkeypatch.setenv(F.URL_ENV, "http://nonexistent.invalid/")
    before = len(server.hits)
    assert F.main(["fetch", "all"]) == 2
    out, err = capsys.readouterr()
    assert out == f"chessboard: present in {data / 'chessboard'} (sha256 verified); nothing downloaded\n"
    failed = [line for line in err.splitlines() if line.startswith("error: ")]
    assert [Path(line.split(": ")[1]).relative_to(data).parts[0] for line in failed] == \
        ["dino", "fountain-P11", "templeRing", "bal"], err
    assert all(line.endswith("(offline? no host name resolved)") for line in failed), err
    assert sorted(os.listdir(data)) == ["chessboard"] and len(server.hits) == before

    # run as a new user would, on the real data path: the set is found where it is, nothing is fetched
    proc = run_cli("fetch", "chessboard", data=tmp_path / "data", url=closed_port_url())
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert proc.stdout.startswith("chessboard: present in ") and "sha256 verified" in proc.stdout


@needs("templeRing", "bal")
def test_archive_sources_unpack_and_verify(server, tmp_path, monkeypatch):
    """The Middlebury zip and the BAL .bz2, as the origins pack them; a 404 origin falls back to the mirror."""
    a = server.url + "/archives"
    temple, bal = F.DATASETS["templeRing"], F.DATASETS["bal"]
    monkeypatch.setitem(F.DATASETS, "templeRing", replace(temple, sources=(
        F.Source("zip", a + "/templeRing.zip", "origin", "templeRing/"),)))
    monkeypatch.setitem(F.DATASETS, "bal", replace(bal, sources=(F.Source("bz2", a, "origin"),)))
    monkeypatch.delenv(F.URL_ENV, raising=False)
    (tmp_path / "ok").mkdir()
    for name in ("templeRing", "bal"):
        rep = F.fetch(name, tmp_path / "ok", progress=False)
        assert rep.n_downloaded == len(F.DATASETS[name].files)
        assert files_under(tmp_path / "ok" / name) == sorted(f.path for f in F.DATASETS[name].files)
        assert F.status(name, dirs=[tmp_path / "ok"]).state == "present"

    # a member that does not unpack to the registered bytes is reported by name and not kept
    monkeypatch.setitem(F.DATASETS, "templeRing", replace(temple, sources=(
        F.Source("zip", a + "/templeRing-bad.zip", "origin", "templeRing/"),)))
    (tmp_path / "bad").mkdir()
    with pytest.raises(F.FetchError, match="sha256 mismatch") as exc:
        F.fetch("templeRing", tmp_path / "bad", progress=False)
    assert exc.value.path == tmp_path / "bad" / "templeRing" / "README.txt"
    assert not any(p.startswith(".fetch-") or p == "README.txt" for p in files_under(tmp_path / "bad" / "templeRing"))

    # the origin is gone (404): the mirror takes over, and the report says so
    monkeypatch.setitem(F.DATASETS, "templeRing", replace(temple, sources=(
        F.Source("zip", a + "/no-such.zip", "origin", "templeRing/"),
        F.Source("files", server.url + "/good/templeRing", "mirror"))))
    rep = F.fetch("templeRing", tmp_path / "bad", progress=False)
    assert len(rep.notes) == 1 and "the origin failed" in rep.notes[0] and "404" in rep.notes[0]
    assert F.status("templeRing", dirs=[tmp_path / "bad"]).state == "present"


@needs("chessboard", "bal")
def test_fetch_all_skips_the_set_without_a_public_download(server, tmp_path, monkeypatch, capsys):
    """Without $LABUTILS_DATA_URL, 'all' means every set with a source; dino gets a note; naming it is an error."""
    small = {n: replace(F.DATASETS[n], sources=(F.Source("files", f"{server.url}/good/{n}", "origin"),))
             for n in ("chessboard", "bal")}
    monkeypatch.setattr(D, "DATASETS", {"dino": F.DATASETS["dino"], **small})
    monkeypatch.setattr(F, "DATASETS", D.DATASETS)
    monkeypatch.setattr(F, "data_dirs", lambda: [tmp_path])      # the data path: this folder only
    monkeypatch.setenv("LABUTILS_DATA", str(tmp_path))
    monkeypatch.delenv(F.URL_ENV, raising=False)
    assert F.main(["fetch", "all"]) == 0
    out, err = capsys.readouterr()
    assert "note: dino: skipped, no public download" in err
    assert [line.split(":")[0] for line in out.splitlines()] == ["chessboard", "bal"]
    assert sorted(os.listdir(tmp_path)) == ["bal", "chessboard"]
    assert F.main(["fetch", "dino"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"error: {tmp_path / 'dino' / 'BAdino2.mat'}: no public download"), line


def test_status_reports_missing(tmp_path):
    assert F.status("dino", dirs=[tmp_path]).state == "missing"
    (tmp_path / "bal").mkdir()
    st = F.status("bal", dirs=[tmp_path])
    assert (st.state, st.folder, st.missing) == ("incomplete", tmp_path / "bal", ["problem-49-7776-pre.txt"])


# --- the command line's failures ------------------------------------------------------------------------------
def test_cli_help_exits_0(tmp_path, capsys):
    proc = run_cli("--help", data=tmp_path)
    assert proc.returncode == 0 and "usage: python -m labutils.data" in proc.stdout, proc.stderr
    for command in ("fetch", "list"):
        with pytest.raises(SystemExit) as exc:
            F.main([command, "--help"])
        assert exc.value.code == 0 and f"usage: python -m labutils.data {command}" in capsys.readouterr().out


def test_cli_unknown_name_names_the_choices(tmp_path):
    proc = run_cli("fetch", "dinosaur", data=tmp_path)
    assert proc.returncode == 2
    (line,) = error_lines(proc)
    assert "'dinosaur'" in line and all(n in line for n in NAMES + ["all"]), line
    assert files_under(tmp_path) == []


def test_cli_checks_the_target_folder_first(tmp_path, monkeypatch, capsys):
    missing = tmp_path / "no" / "such"
    proc = run_cli("fetch", "bal", data=missing, url=closed_port_url())
    assert proc.returncode == 2
    (line,) = error_lines(proc)
    assert line == f"error: {missing}: the data folder does not exist (create it, or set $LABUTILS_DATA to another one)"
    assert not missing.exists()
    monkeypatch.setenv("LABUTILS_DATA", "none")
    assert F.main(["fetch", "bal"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("error: $LABUTILS_DATA: is 'none'"), line


def test_list_without_data(monkeypatch, capsys):
    monkeypatch.setenv("LABUTILS_DATA", "none")
    assert F.main(["list"]) == 0
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if line.split()[:1] and line.split()[0] in NAMES]
    assert [r[0] for r in rows] == NAMES and all(r[-1] == "missing" for r in rows)
    assert "licence: Apache-2.0" in out and "cite: S. Agarwal" in out


def test_data_entry_point_has_no_runpy_warning(tmp_path):
    proc = run_cli("fetch", "dinosaur", data=tmp_path)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr



def test_a_ctrl_c_mid_fetch_leaves_no_folder(tmp_path, monkeypatch):
    """The folders a fetch made are removed when it stops, by a failure or by Ctrl-C (``KeyboardInterrupt``, which
    the command line reports on one line with exit status 130)."""
    def interrupted(src, folder, todo, bar):
        (folder / "gt_dense_cameras").mkdir(parents=True)
        raise KeyboardInterrupt
    monkeypatch.setitem(F._FETCHERS, "files", interrupted)
    with pytest.raises(KeyboardInterrupt):
        F.fetch("fountain-P11", tmp_path, base_url="http://nonexistent.invalid/", progress=False)
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "fountain-P11").mkdir()                  # a folder that was there before stays
    with pytest.raises(KeyboardInterrupt):
        F.fetch("fountain-P11", tmp_path, base_url="http://nonexistent.invalid/", progress=False)
    assert [p.name for p in tmp_path.rglob("*")] == ["fountain-P11"]
