"""Shared fixtures: small meshes and models used across the sim tests."""

import gc
import os
import re
import uuid
from pathlib import Path

import numpy as np
import psycopg
import pytest

from sessions.config import prepare_rendering
from sim.fem import Material, TissueModel
from sim.mesh import box_mesh

prepare_rendering()  # as the CLI does: offscreen EGL rendering without a display

POSTGRES_ADMIN = os.environ.get("VASCSIM_TEST_POSTGRES", "postgresql://postgres@127.0.0.1:5432/test")


@pytest.fixture(scope="session")
def cube():
    """The paper's test cube: 10 mm side, 729 nodes, 3072 elements."""
    return box_mesh(0.01, 8)


@pytest.fixture(scope="session")
def small_box():
    return box_mesh((0.004, 0.005, 0.003), (4, 5, 3))


@pytest.fixture(scope="session")
def cube_model(cube, tmp_path_factory):
    model = TissueModel(cube, Material(20e3, 0.45), cube.node_sets["z0"])
    model.precompute(cache_dir=tmp_path_factory.mktemp("cache"))
    return model


def top_centre_triangle(mesh):
    """An exterior triangle on the top face touching the node nearest the face centre."""
    top = mesh.node_sets["z1"]
    centre = mesh.points[top].mean(axis=0)
    node = top[np.argmin(np.linalg.norm(mesh.points[top] - centre, axis=1))]
    normals = mesh.surface_normals
    candidates = np.flatnonzero(np.any(mesh.surface_triangles == node, axis=1) & (normals[:, 2] > 0.99))
    return mesh.surface_triangles[candidates[0]]


@pytest.fixture(scope="session")
def wall_patch_biphase():
    """A precomputed biphase 1.5 mm wall patch (12 x 10 mm) held on three sides; its free x1
    edge is the wound edge the scripted suturing pass bites near."""
    from sim.fem import BiphaseTissue

    mesh = box_mesh((0.012, 0.01, 0.0015), (12, 10, 3))
    fixed = np.concatenate([mesh.node_sets[k] for k in ("x0", "y0", "y1")])
    tissue = BiphaseTissue.build(mesh, fixed)
    tissue.precompute(use_cache=False)
    return tissue


# Catalog fixtures: every catalog test runs on SQLite and on the PostgreSQL server at 127.0.0.1:5432.


@pytest.fixture(params=["sqlite", "postgresql"])
def catalog_url(request, tmp_path):
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'catalog.sqlite'}"
        return
    name = f"vascsim_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(POSTGRES_ADMIN, autocommit=True) as admin:
        admin.execute(f'CREATE DATABASE "{name}"')
    base = POSTGRES_ADMIN.rsplit("/", 1)[0]
    yield f"{base}/{name}"
    with psycopg.connect(POSTGRES_ADMIN, autocommit=True) as admin:
        admin.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


@pytest.fixture
def open_catalog():
    """Opens catalogs and disposes their connection pools at teardown (no connection left to the GC)."""
    from sessions.catalog import Catalog

    opened = []

    def factory(url):
        catalog = Catalog(url)
        opened.append(catalog)
        return catalog

    yield factory
    for catalog in opened:
        catalog.close()


@pytest.fixture
def home(tmp_path, catalog_url, monkeypatch):
    """VASCSIM_HOME and VASCSIM_DATABASE_URL for CLI tests."""
    folder = tmp_path / "home"
    monkeypatch.setenv("VASCSIM_HOME", str(folder))
    monkeypatch.setenv("VASCSIM_DATABASE_URL", catalog_url)
    return folder


# One reduced demo (SQLite, local files) for every test that reads a demo study: it runs once per
# test session and each test works on its own copy, so a test that changes the catalog changes only
# its copy. Two experts (two sessions each), three trainees (three practice sessions and a
# retention), the interrupted stitch only: 16 sessions, enough for test-retest (five participants).
REDUCED_DEMO_SIZE = dict(
    experts=2,
    expert_sessions=2,
    trainees=3,
    practice_sessions=3,
    retention=True,
    closures=False,
    benchmark_override="test fixture: two experts and three trainees give no AUC interval",
)


@pytest.fixture(scope="session")
def demo_template(tmp_path_factory):
    from sessions.catalog import Catalog
    from sessions.demo import DemoSize, run_demo

    home = tmp_path_factory.mktemp("demo-template")
    catalog = Catalog(f"sqlite:///{home / 'catalog.sqlite'}")
    # in this process: the other pytest worker has the second core (a pool of two would spawn two
    # interpreters that import everything again; the whole demo's tests run the pool)
    result = run_demo(catalog, home, DemoSize(**REDUCED_DEMO_SIZE), workers=1)
    catalog.close()
    return home, result


def repoint_session_folders(url: str, old: Path, new: Path) -> None:
    """Point a copied catalog's session directories from the template's home ``old`` to ``new``."""
    from sqlalchemy import create_engine, text

    engine = create_engine(url)
    with engine.begin() as connection:
        connection.execute(
            text("UPDATE sessions SET directory = replace(directory, :old, :new)"),
            {"old": str(old), "new": str(new)},
        )
    engine.dispose()


@pytest.fixture(scope="session")
def copy_demo(demo_template):
    """``copy_demo(folder)`` copies the reduced demo's home (catalog, recordings, reports, cache) into
    ``folder`` and points the catalog's session directories at the copy; returns the catalog URL."""
    import shutil

    template, _ = demo_template

    def copy(folder):
        shutil.copytree(template, folder, dirs_exist_ok=True)
        url = f"sqlite:///{folder / 'catalog.sqlite'}"
        repoint_session_folders(url, template, folder)
        return url

    return copy


@pytest.fixture(scope="module")
def demo_catalog(tmp_path_factory, copy_demo):
    """A copy of the reduced demo shared by one test module: (catalog, home)."""
    from sessions.catalog import Catalog

    home = tmp_path_factory.mktemp("home")
    catalog = Catalog(copy_demo(home))
    yield catalog, home
    catalog.close()


# One synthetic bench video and its ChArUco calibration for the files that track it (14 s to render and
# encode): built once per test session, their files kept on one worker (pytest_xdist_make_scheduler).
@pytest.fixture(scope="session")
def bench_calibration(tmp_path_factory):
    """(camera calibrated from twelve ChArUco views, the saved camera file)."""
    from sim.tracking.camera import calibrate_charuco
    from sim.tracking.synthetic import charuco_views

    camera = calibrate_charuco(charuco_views(count=12))
    path = camera.save(tmp_path_factory.mktemp("camera") / "camera.json")
    return camera, path


@pytest.fixture(scope="session")
def bench_video(tmp_path_factory):
    """(video file, frame times (s), true tip path (m)): six seconds of a flat-marked needle holder."""
    from sim.tracking.synthetic import write_bench_video

    path = tmp_path_factory.mktemp("video") / "bench.mp4"
    time, truth = write_bench_video(path, duration_s=6.0, fps=30)
    return path, time, truth


@pytest.fixture(scope="session")
def display():
    """A virtual 1366x768 X display for window tests (Xvfb picks a free display number itself)."""
    from tests.xvfb import start_virtual_display

    server, name = start_virtual_display()
    yield name
    server.terminate()
    server.wait(10)


SHARED_DEMO_GROUP = "reduced-demo"
DEMO_FIXTURES = ("demo_template", "copy_demo", "demo_catalog")
SHARED_GROUPS = {SHARED_DEMO_GROUP: DEMO_FIXTURES, "bench-video": ("bench_video", "bench_calibration")}
"""The costly session fixtures, by the name of the worker group whose files share each."""


def files_naming(fixtures: tuple[str, ...]) -> set[str]:
    """The test files (paths from the repository's root) that name one of ``fixtures``: the file level
    is all that pytest-xdist's controller sees when it hands out work."""
    root = Path(__file__).parent
    named = re.compile(r"\b(" + "|".join(fixtures) + r")\b")
    return {
        path.relative_to(root.parent).as_posix()
        for path in root.rglob("test_*.py")
        if named.search(path.read_text(encoding="utf-8"))
    }


def files_reading_the_demo() -> set[str]:
    """The test files that name a fixture of the shared reduced demo."""
    return files_naming(DEMO_FIXTURES)


def pytest_xdist_make_scheduler(config, log):
    """How scripts/test's two workers share the tests: a file's tests stay together (its module
    fixtures are built once), and the files that read one of the costly session fixtures (the reduced
    demo, the bench video) go to one worker each, so each is built once in the suite, not once per
    worker. A file naming fixtures of two groups goes with the first."""
    from xdist.scheduler import LoadScopeScheduling

    group_of: dict[str, str] = {}
    for group, fixtures in SHARED_GROUPS.items():
        for file in files_naming(fixtures):
            group_of.setdefault(file, group)

    class ByFileSharedTogether(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            file = nodeid.split("::", 1)[0]
            return group_of.get(file, file)

    return ByFileSharedTogether(config, log)


def pytest_collection_modifyitems(config, items):
    """A test that reads the demo through a fixture its file does not name would build the demo
    on a second worker: say so rather than silently paying for it."""
    demo_files = files_reading_the_demo()
    missed = {item.nodeid.split("::", 1)[0] for item in items if "demo_template" in item.fixturenames}
    missed -= demo_files
    if missed:
        raise pytest.UsageError(
            f"{', '.join(sorted(missed))} read(s) the shared reduced demo without naming one of "
            f"{', '.join(DEMO_FIXTURES)}: name it in the file so the demo's tests share one worker"
        )


RINGS = Path("/dev/shm")


def _rings() -> set[str]:
    """The recorder's ring files on tmpfs now (recorder.ring)."""
    return {path.name for path in RINGS.glob("vascsim-ring-*")} if RINGS.is_dir() else set()


def pytest_sessionstart(session):
    session.config._rings_before = _rings()


def _own_resource_tracker(pid: int) -> bool:
    """multiprocessing's resource tracker of this test process: started by the first spawn-context
    pool (e.g. the demo's), with the environment of the test that started it, and ending with this
    process, not left behind by a test."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            parent = int(stat.read().rsplit(")", 1)[1].split()[1])
        with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
            words = cmdline.read()
    except (OSError, ValueError, IndexError):
        return False
    return parent == os.getpid() and b"multiprocessing.resource_tracker" in words


def pytest_sessionfinish(session, exitstatus):
    """Issue 45, seen 13: the suite leaves no process behind. Anything still running that was started
    with this run's temporary folder in its command line or environment (a killed run's worker, a
    server a test forgot) fails the run, and is stopped."""
    import signal

    from tests.processes import started_under, still_running

    if getattr(session.config, "workerinput", None) is not None:
        return
    factory = getattr(session.config, "_tmp_path_factory", None)
    if factory is None:
        return
    base = str(factory.getbasetemp())
    left = [pid for pid in started_under(base) if not _own_resource_tracker(pid)]
    left = still_running(left, within=10.0)
    if left:
        names = []
        for pid in left:
            try:
                with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
                    words = cmdline.read().replace(b"\0", b" ").decode(errors="replace")
            except OSError:
                words = ""
            names.append(f"{pid} {words[:120]}")
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        print(f"\nprocesses left running by the tests (now killed): {'; '.join(names)}")
        session.exitstatus = 1
    # nor memory: a writer neither closed nor recovered leaves its ring (19 MB of tmpfs) for ever
    leaked = sorted(_rings() - getattr(session.config, "_rings_before", set()))
    if leaked:
        for name in leaked:
            (RINGS / name).unlink(missing_ok=True)
        print(f"\n{len(leaked)} recorder ring(s) left in {RINGS} by the tests (now removed): {leaked[0]} ...")
        session.exitstatus = 1


def pytest_collection_finish(session):
    """The objects every test module's imports made (half a million in a worker) are moved out of the
    collector's way: each full collection in the run no longer walks them (about a second a worker
    in tests/sim and tests/metrics; gc.freeze, as the real-time processes do)."""
    gc.freeze()
