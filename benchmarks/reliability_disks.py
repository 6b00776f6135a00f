"""Full and read-only disks under a run (issue 13's audit class "full or read-only disks"): each
case runs `gyrobench run ... --json` with its raw files on a disk that is or becomes full or
read-only, and checks that it ended clean: safe state confirmed, one clear message (the
end_reason starting "raw data: "), a non-zero exit, no traceback or crash on stderr, and every
raw file left behind readable by h5py (every stream, bench time increasing) and h5dump.  A run
the CLI refuses before it starts (one line "gyrobench: ...", exit 1 or 2, no file) is clean too.

    sudo .venv/bin/python benchmarks/reliability_disks.py

Needs root (tmpfs mounts).  Prints one line per case, then "full or read-only disks: tried N, clean M".
"""

from __future__ import annotations

import fcntl
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np

GYROBENCH = [sys.executable, "-m", "bench.cli"]
DAMPING = ["run", "hrg-damping", "--seed", "1"]
EXT4_IOC_SHUTDOWN = 0x8004587D  # _IOR('X', 125, __u32)
SPIN = ["run", "table-spin", "--set", "hold_s=300", "--seed", "1"]


def mount_tmpfs(path: Path, size: str, *options: str) -> None:
    path.mkdir(parents=True, exist_ok=True)
    subprocess.run(["mount", "-t", "tmpfs", "-o", ",".join([f"size={size}", *options]), "tmpfs", str(path)],
                   check=True)


def fill(path: Path, leave_bytes: int) -> None:
    """Fill the file system of path until leave_bytes are free."""
    st = os.statvfs(path)
    free = st.f_bavail * st.f_frsize
    with open(path / "filler", "wb") as f:
        f.write(bytes(max(0, free - leave_bytes)))


def readable(path: Path) -> str | None:
    """None when every stream reads back with increasing bench time and h5dump reads the file."""
    try:
        with h5py.File(path, "r") as f:
            for name, ds in f["streams"].items():
                cols = json.loads(ds.attrs["columns"])
                a = ds[...]
                if "t_s" in cols and len(a) > 1 and not np.all(np.diff(a[:, cols.index("t_s")]) > 0):
                    return f"{name}: bench time not increasing"
            [json.loads(x) for x in f["log"].asstr()[...]]
    except Exception as exc:  # noqa: BLE001 - any failure to read is the finding
        return f"h5py: {type(exc).__name__}: {exc}"
    if shutil.which("h5dump"):
        done = subprocess.run(["h5dump", str(path)], capture_output=True)
        if done.returncode:
            return f"h5dump exit {done.returncode}"
    return None


def judge(done: subprocess.CompletedProcess, raw_dir: Path, *, expect_fail: bool = True) -> tuple[bool, str]:
    problems = []
    if "Traceback" in done.stderr or "Segmentation" in done.stderr:
        problems.append("traceback/crash on stderr")
    if "internal error" in done.stderr:
        problems.append("internal error")
    if done.returncode < 0 or done.returncode > 2:
        problems.append(f"exit {done.returncode}")
    try:
        out = json.loads(done.stdout)
    except ValueError:
        out = None
    err = done.stderr.strip()
    refused = out is None and done.returncode in (1, 2) and len(err.splitlines()) == 1 and err.startswith("gyrobench: ")
    if out is None and not refused:
        problems.append(f"no JSON result and no one-line refusal (stderr: {err[-200:]!r})")
    reason = err if refused else "" if out is None else out["end_reason"]
    if refused:  # the CLI refused before the run started: nothing moved, no file
        pass
    elif out is not None:
        if not out["safe_state"]:
            problems.append("safe state not confirmed")
        if expect_fail:
            if done.returncode == 0:
                problems.append("exit 0")
            if not reason.startswith("raw data: "):
                problems.append(f"unclear message {reason!r}")
        elif done.returncode != 0:
            problems.append(f"exit {done.returncode}: {reason}")
    files = [p for p in raw_dir.glob("*") if p.name not in ("filler", "lost+found")] if raw_dir.is_dir() else []
    notes = []
    for p in files:
        if ".reserve-" in p.name:  # a dead disk could not unlink it; the next run there removes it
            notes.append(f"left behind: {p.name}")
        elif p.suffix != ".h5":
            problems.append(f"left behind: {p.name}")
        elif (why := readable(p)) is not None:
            problems.append(f"{p.name} unreadable: {why}")
    return not problems, "; ".join(problems) or "; ".join([reason[:150], *notes])


def run(args: list[str], raw_dir: Path, store: Path, *, during: Callable[[], None] | None = None,
        limit_bytes: int | None = None) -> subprocess.CompletedProcess:
    def preexec() -> None:
        if limit_bytes is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    cmd = GYROBENCH + args + ["--json", "--runs-dir", str(raw_dir), "--results", str(store)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=preexec)
    if during is not None:
        threading.Thread(target=during, daemon=True).start()
    out, err = proc.communicate(timeout=600)
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def when_file_reaches(raw_dir: Path, size: int, action: Callable[[], None]) -> Callable[[], None]:
    def watch() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            files = list(raw_dir.glob("*.h5"))
            if files and files[0].stat().st_size >= size:
                action()
                return
            time.sleep(0.02)

    return watch


def main() -> int:
    if os.geteuid() != 0:
        print("needs root (tmpfs mounts)")
        return 2
    tried = clean = 0
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        store = tmp / "store.sqlite"
        cases: list[tuple[str, Callable[[Path], subprocess.CompletedProcess], bool]] = []

        def tmpfs_case(size: str, args: list[str], prefill: int | None = None, expect_fail: bool = True):
            def go(d: Path) -> subprocess.CompletedProcess:
                mount_tmpfs(d, size)
                if prefill is not None:
                    fill(d, prefill)
                return run(args, d, store)

            return go, expect_fail

        def filled_mid_run(d: Path) -> subprocess.CompletedProcess:
            mount_tmpfs(d, "16m")
            return run(DAMPING, d, store, during=when_file_reaches(d, 3_000_000, lambda: fill(d, 0)))

        def read_only(d: Path) -> subprocess.CompletedProcess:
            mount_tmpfs(d, "8m", "ro")
            return run(SPIN, d, store)

        def is_a_file(d: Path) -> subprocess.CompletedProcess:
            d.parent.mkdir(parents=True, exist_ok=True)
            d.write_text("not a directory")
            done = run(SPIN, d, store)
            d.unlink()
            return done

        def under_a_file(d: Path) -> subprocess.CompletedProcess:
            d.parent.mkdir(parents=True, exist_ok=True)
            d.write_text("not a directory")
            done = run(SPIN, d / "runs", store)
            d.unlink()
            return done

        def size_limit(d: Path) -> subprocess.CompletedProcess:
            d.mkdir(parents=True)
            return run(DAMPING, d, store, limit_bytes=4_000_000)

        def shut_down_mid_run(d: Path) -> subprocess.CompletedProcess:
            """An ext4 disk that fails mid-run (EXT4_IOC_SHUTDOWN: every later write is an I/O error);
            judged after mounting it again."""
            img = tmp / "ext4.img"
            subprocess.run(["truncate", "-s", "64M", str(img)], check=True)
            subprocess.run(["mkfs.ext4", "-q", "-F", str(img)], check=True)
            d.mkdir(parents=True)
            subprocess.run(["mount", "-o", "loop", str(img), str(d)], check=True)

            def shut_down() -> None:
                fd = os.open(d, os.O_RDONLY)
                try:
                    fcntl.ioctl(fd, EXT4_IOC_SHUTDOWN, b"\0\0\0\0")
                finally:
                    os.close(fd)

            done = run(DAMPING, d, store, during=when_file_reaches(d, 3_000_000, shut_down))
            subprocess.run(["umount", str(d)], check=True)
            subprocess.run(["mount", "-o", "loop", str(img), str(d)], check=True)
            return done

        cases += [
            ("tmpfs 8 MB, hrg-damping (fills in the record)", *tmpfs_case("8m", DAMPING)),
            ("tmpfs 3 MB, hrg-damping (fills before the record)", *tmpfs_case("3m", DAMPING)),
            ("tmpfs 1.5 MB, hrg-damping (full at the first flush)", *tmpfs_case("1536k", DAMPING)),
            ("tmpfs with 0.5 MB free at the start", *tmpfs_case("4m", SPIN, prefill=500_000)),
            ("tmpfs 28 MB: the run fits, compressing it at close does not", *tmpfs_case("28m", DAMPING,
                                                                                          expect_fail=False)),
            ("tmpfs filled by another process mid-run", filled_mid_run, True),
            ("read-only tmpfs", read_only, True),
            ("runs dir is a file", is_a_file, True),
            ("runs dir under a file", under_a_file, True),
            ("file size limit 4 MB (a quota), hrg-damping", size_limit, True),
            ("ext4 disk failing mid-run (shut down: I/O errors)", shut_down_mid_run, True),
        ]
        for k, (name, go, expect_fail) in enumerate(cases):
            d = tmp / f"case{k}"
            t0 = time.monotonic()
            try:
                done = go(d)
                ok, detail = judge(done, d, expect_fail=expect_fail)
            finally:
                subprocess.run(["umount", str(d)], capture_output=True, check=False)
            tried += 1
            clean += ok
            print(f"{'clean' if ok else 'NOT CLEAN':9} {name}: {detail}  ({time.monotonic() - t0:.1f} s)", flush=True)
    print(f"full or read-only disks: tried {tried}, clean {clean}")
    return 0 if clean == tried else 1


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.default_int_handler)
    sys.exit(main())
