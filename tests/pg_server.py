"""A throw-away PostgreSQL server of one's own (`.ci/start-postgres`) that a test or the store audit
may black-hole (SIGSTOP its postmaster and backends: connections are accepted by the kernel and
never answered), resume, or restart; only this server's processes are signalled, found from its
data directory's postmaster.pid, never by name."""

from __future__ import annotations

import glob
import os
import signal
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
START = ROOT / ".ci" / "start-postgres"


def available() -> bool:
    """Whether PostgreSQL's server binaries are installed (start-postgres can start one)."""
    return bool(glob.glob("/usr/lib/postgresql/*/bin/initdb")) or os.geteuid() == 0


class PgServer:
    """One server started by `.ci/start-postgres`: its URL and data directory."""

    def __init__(self) -> None:
        out = subprocess.run([str(START)], capture_output=True, text=True, timeout=180, check=True)
        self.url = out.stdout.strip().splitlines()[-1]
        self.port = int(self.url.rsplit(":", 1)[1].split("/", 1)[0])
        self.data_dir = Path(f"/tmp/gyrobench-pg-{self.port}")
        self.stopped = False

    def pids(self) -> list[int]:
        """The postmaster and its children (the backends and helpers) of this server only."""
        pm = int((self.data_dir / "postmaster.pid").read_text().split()[0])
        kids = []
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                fields = stat.read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue  # a process that ended meanwhile
            if fields[1] == str(pm):  # its parent process id
                kids.append(int(stat.parent.name))
        return [pm, *sorted(kids)]

    def black_hole(self) -> None:
        """Stop every process of this server (SIGSTOP): it accepts connections and never answers."""
        for pid in self.pids():
            _signal(pid, signal.SIGSTOP)
        self.stopped = True

    def resume(self) -> None:
        for pid in self.pids():
            _signal(pid, signal.SIGCONT)
        self.stopped = False

    def _pg_ctl(self, *args: str) -> None:
        bin_dir = sorted(glob.glob("/usr/lib/postgresql/*/bin"))[-1]
        cmd = [f"{bin_dir}/pg_ctl", "-D", str(self.data_dir), "-l", str(self.data_dir / "server.log"), *args]
        if os.geteuid() == 0:
            cmd = ["runuser", "-u", "postgres", "--", *cmd]
        # no pipes: the server started inherits pg_ctl's output and would hold a pipe open for ever
        subprocess.run(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                       timeout=120, check=True)

    def restart(self) -> None:
        """pg_ctl restart (fast): every connection open now is dropped; returns when it answers."""
        if self.stopped:
            self.resume()
        self._pg_ctl("-m", "fast", "-w", "-t", "60", "restart")

    def require_password(self, user: str, password: str) -> str:
        """A role `user` that logs in over TCP with `password` only (scram-sha-256), owning a schema
        of its name; the URL (without the password) of that schema."""
        from sqlalchemy import create_engine, text

        hba = self.data_dir / "pg_hba.conf"
        hba.write_text(f"host all {user} 127.0.0.1/32 scram-sha-256\n" + hba.read_text())
        admin = create_engine(self.url, isolation_level="AUTOCOMMIT")
        with admin.connect() as conn:
            conn.execute(text(f"CREATE ROLE {user} LOGIN PASSWORD '{password}'"))
            conn.execute(text(f"CREATE SCHEMA {user} AUTHORIZATION {user}"))
        admin.dispose()
        self._pg_ctl("reload")
        return self.url.replace("postgres@", f"{user}@", 1) + f"?options=-csearch_path%3D{user}"

    def stop(self) -> None:
        """Stop the server and remove its directory (resumed first if black-holed)."""
        if self.stopped:
            self.resume()
        subprocess.run([str(START), "--stop", self.url], capture_output=True, text=True, timeout=120)


def _signal(pid: int, sig: int) -> None:
    """Send sig to pid; a backend that ended between the listing and the signal has nothing to stop."""
    try:
        os.kill(pid, sig)
    except ProcessLookupError:
        pass
