import os
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

ROOT = Path(__file__).resolve().parents[1]


def pytest_configure(config):
    """Under xdist (-n N) the controller fills the compiled-kernel cache (simulators.warm) before the
    workers start, when it is not filled yet: no two workers compile and write the same kernels."""
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    from bench import kernel_cache

    if not kernel_cache.is_filled():
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
        subprocess.run([sys.executable, "-m", "simulators.warm"], cwd=ROOT, env=env, check=True)


#: GYROBENCH_TEST_CPU_LOG=FILE: each test's CPU seconds (this process, and the children it waited
#: for: the CLI subprocesses) and wall seconds, setup to teardown, appended as tab-separated lines
#: (every xdist worker appends to the same file) - the suite's cost on 2 cores is CPU, not wall;
#: then the xdist worker and the end's Unix time, to see how the workers' last tests end
CPU_LOG_ENV = "GYROBENCH_TEST_CPU_LOG"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """With $GYROBENCH_TEST_CPU_LOG set: one line per test, `nodeid cpu_self_s cpu_children_s wall_s worker end_s`."""
    log = os.environ.get(CPU_LOG_ENV)
    if not log:
        yield
        return
    import resource
    import time

    def cpu() -> tuple[float, float]:
        me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
        return me.ru_utime + me.ru_stime, kids.ru_utime + kids.ru_stime

    (self0, kids0), wall0 = cpu(), time.monotonic()
    yield
    (self1, kids1), wall_s = cpu(), time.monotonic() - wall0
    with open(log, "a", encoding="utf-8") as f:  # one short write per line: lines of workers do not mix
        worker = os.environ.get("PYTEST_XDIST_WORKER", "-")
        f.write(f"{item.nodeid}\t{self1 - self0:.2f}\t{kids1 - kids0:.2f}\t{wall_s:.2f}\t{worker}\t{time.time():.2f}\n")


#: `make test`'s serial pass collects only the test files holding this text (the Makefile's grep):
#: collecting all of them again (~11 s of CPU) for 51 tests was the pass's largest single cost
SERIAL_MARK_TEXT = "mark.serial"


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """A test marked `serial` in a file without SERIAL_MARK_TEXT (a mark added by a hook or a
    helper) would be left out of both of `make test`'s passes: refuse the run instead."""
    texts: dict[str, bool] = {}
    for item in items:
        if item.get_closest_marker("serial") is None:
            continue
        path = str(item.path)
        if path not in texts:  # the grep reads tests/test_*.py, not subfolders
            texts[path] = item.path.parent == ROOT / "tests" and SERIAL_MARK_TEXT in item.path.read_text()
        if not texts[path]:
            raise pytest.UsageError(f"{item.nodeid} is marked serial outside a tests/test_*.py file with "
                                    f"'{SERIAL_MARK_TEXT}': `make test`'s serial pass (its grep) would not run it")


@pytest.hookimpl(tryfirst=True, optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """`--dist loadfile`: whole test files, handed out costliest first (tests/xdist_units.py)."""
    if config.getvalue("dist") != "loadfile":
        return None
    from tests.xdist_units import make_scheduler

    return make_scheduler(config, log)


PG_URL_ENV = "GYROBENCH_TEST_PG_URL"  # e.g. postgresql+psycopg://postgres@127.0.0.1:5432/gyrobench_test


def _missing(reason: str) -> None:
    """Under CI a test whose real part (a PostgreSQL server) is missing fails; elsewhere it skips."""
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"{reason} (CI=true: the PostgreSQL tests must run; .ci/run starts a server)")
    pytest.skip(reason)


@pytest.fixture
def pg_url():
    """A fresh, empty schema on the test PostgreSQL server ($GYROBENCH_TEST_PG_URL), as a store URL."""
    base = os.environ.get(PG_URL_ENV)
    if not base:
        _missing(f"{PG_URL_ENV} is not set: no PostgreSQL server to test against")
    from sqlalchemy import create_engine, text
    from sqlalchemy.exc import SQLAlchemyError

    try:
        admin = create_engine(base, isolation_level="AUTOCOMMIT")
    except ImportError as exc:
        _missing(f"no PostgreSQL driver: {exc}")
    schema = f"t_{uuid.uuid4().hex[:12]}"
    try:
        with admin.connect() as conn:
            conn.execute(text(f"CREATE SCHEMA {schema}"))
    except SQLAlchemyError as exc:
        admin.dispose()
        _missing(f"PostgreSQL at {base} is unreachable: {str(getattr(exc, 'orig', exc)).splitlines()[0]}")
    sep = "&" if "?" in base else "?"
    yield f"{base}{sep}options=-csearch_path%3D{schema}"
    with admin.connect() as conn:
        conn.execute(text(f"DROP SCHEMA {schema} CASCADE"))
    admin.dispose()


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request, tmp_path):
    """A fresh results store URL on each engine: a SQLite file, and a schema on PostgreSQL."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'results.sqlite'}"
    return request.getfixturevalue("pg_url")


@pytest.fixture(autouse=True, scope="session")
def _window_settings_apart(tmp_path_factory):
    """The window remembers its DUT and operator fields in QSettings: tests keep theirs in a
    temporary folder, never in the user's own settings (and never from one session to the next)."""
    try:
        from PySide6.QtCore import QSettings
    except ImportError:
        yield
        return
    path = str(tmp_path_factory.mktemp("qsettings"))
    for fmt in (QSettings.Format.NativeFormat, QSettings.Format.IniFormat):
        QSettings.setPath(fmt, QSettings.Scope.UserScope, path)
    yield


@pytest.fixture
def plots(qtbot):
    """The window's live plots, shown at 1000 x 700 offscreen, redrawn at 25 Hz from 400 points a curve."""
    from bench.gui.plots import LivePlots

    w = LivePlots(refresh_hz=25.0, max_points=400)
    qtbot.addWidget(w)
    w.resize(1000, 700)
    w.show()
    yield w
    w.shutdown()


@pytest.hookimpl(trylast=True)
def pytest_collection_finish(session):
    """Once the tests are collected (every module of ours, numpy, numba, Qt imported: ~280 000
    objects), collect once and freeze what is left: the collector then never walks those objects
    again (until the first Qt test's collection below puts them back).  A full collection (the
    collector's own every so often) cost ~0.1-0.2 s each in a worker before; objects a test creates
    are collected as ever."""
    import gc

    gc.collect()
    gc.freeze()


@pytest.fixture(autouse=True)
def _qt_garbage_collected_in_the_gui_thread(request):
    """After a test that used Qt, its cyclic garbage is collected here, in the GUI thread: left to the
    collector, Qt objects were freed from whatever thread allocated next (a station's server threads
    in the next test), and pytest-qt's event processing then crashed the worker (CI, twice).
    What existed before the test is set aside (gc.freeze) while the objects the test made are
    collected, then put back: a full collection walked a late worker's ~250 000 older objects,
    0.15-0.4 s after every Qt test (py-spy of a suite pass: ~2 % of it); garbage among the older
    objects is the collector's as ever (it is not Qt's: the test made the Qt objects)."""
    qt = bool({"qtbot", "qapp"} & set(request.fixturenames))
    if qt:
        import gc

        gc.freeze()
    yield
    if qt:
        gc.collect()
        gc.unfreeze()
