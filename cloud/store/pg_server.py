"""A throwaway PostgreSQL server in a temporary directory, for tests and benchmarks.

It runs the distribution's own ``initdb``/``pg_ctl`` (Debian: ``/usr/lib/postgresql/<v>/bin``,
installed by ``make system-deps``) on 127.0.0.1 at a free port with a random password, so what
the tests exercise is the real server the deployment uses. PostgreSQL refuses to run as root: as
root the cluster belongs to the ``postgres`` account the Debian package creates and every
server command runs through ``runuser``. ``PostgresUnavailable`` says in one line why a server
cannot be had here (no binaries, no account, initdb or start-up failed).
"""

from __future__ import annotations

import glob
import os
import pwd
import secrets
import shutil
import socket
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import PostgresUnavailable

SERVER_USER = "postgres"  # the account Debian's postgresql package creates


def find_bin_dir() -> Path:
    """The directory holding ``initdb`` and ``pg_ctl``: ``DARKREAD_PG_BIN``, the newest
    ``/usr/lib/postgresql/*/bin``, or wherever ``PATH`` finds ``pg_ctl``."""
    override = os.environ.get("DARKREAD_PG_BIN")
    candidates = [Path(override)] if override else []
    versions = sorted(glob.glob("/usr/lib/postgresql/*/bin"), key=lambda p: int(Path(p).parent.name), reverse=True)
    candidates += [Path(p) for p in versions]
    on_path = shutil.which("pg_ctl")
    if on_path:
        candidates.append(Path(on_path).resolve().parent)
    for directory in candidates:
        if (directory / "initdb").is_file() and (directory / "pg_ctl").is_file():
            return directory
    raise PostgresUnavailable(
        "no PostgreSQL server binaries (initdb, pg_ctl): install Debian's postgresql package "
        "(make system-deps as root) or set DARKREAD_PG_BIN"
    )


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@dataclass
class TemporaryPostgres:
    """``start()`` a private cluster, ``url(db)`` to reach it, ``create_database``, ``stop()``."""

    durable: bool = False  # fsync on (benchmarks); tests run with fsync off, it changes no semantics
    port: int = 0
    password: str = field(default_factory=lambda: secrets.token_hex(12), repr=False)
    root: Path | None = None
    _bin: Path | None = None
    _run_as: str | None = None

    user = "darkread"

    def url(self, database: str = "postgres") -> str:
        return f"postgresql://{self.user}:{self.password}@127.0.0.1:{self.port}/{database}"

    def _command(self, *argv: str) -> list[str]:
        assert self._bin is not None  # noqa: S101 - set by start()
        command = [str(self._bin / argv[0]), *argv[1:]]
        return ["runuser", "-u", self._run_as, "--", *command] if self._run_as else command

    def _run(self, *argv: str, timeout_s: float = 60) -> None:
        done = subprocess.run(self._command(*argv), capture_output=True, text=True, timeout=timeout_s, check=False)  # noqa: S603
        if done.returncode != 0:
            tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
            raise PostgresUnavailable(f"{argv[0]} failed ({done.returncode}): {' / '.join(tail)}")

    def start(self) -> TemporaryPostgres:
        self._bin = find_bin_dir()
        if os.geteuid() == 0:
            try:
                owner = pwd.getpwnam(SERVER_USER)
            except KeyError:
                raise PostgresUnavailable(
                    f"running as root and there is no {SERVER_USER!r} account to run the server as "
                    "(Debian's postgresql package creates it)"
                ) from None
            self._run_as = SERVER_USER
        self.root = Path(tempfile.mkdtemp(prefix="darkread-pg-"))
        if self._run_as:
            os.chown(self.root, owner.pw_uid, owner.pw_gid)
        data, pwfile = self.root / "data", self.root / "pwfile"
        pwfile.write_text(self.password + "\n")
        if self._run_as:
            os.chown(pwfile, owner.pw_uid, owner.pw_gid)
        pwfile.chmod(0o600)
        self._run("initdb", "-D", str(data), "-U", self.user, f"--pwfile={pwfile}", "--auth=scram-sha-256",
                  "-E", "UTF8", "--locale=C", "--no-sync")  # fmt: skip
        pwfile.unlink()
        self.port = self.port or _free_port()
        self.resume()
        return self

    def resume(self) -> None:
        """Start the server on its data directory (after ``start()`` made it, or after ``halt()``)."""
        assert self.root is not None  # noqa: S101 - start() first
        options = f"-c listen_addresses=127.0.0.1 -p {self.port} -k {self.root} -c max_connections=200"
        if not self.durable:
            options += " -c fsync=off -c full_page_writes=off"
        self._run("pg_ctl", "-D", str(self.root / "data"), "-l", str(self.root / "server.log"), "-o", options,
                  "-w", "-t", "60", "start")  # fmt: skip

    def halt(self) -> None:
        """Stop the server at once (an outage), keeping its data for ``resume()``."""
        assert self.root is not None  # noqa: S101 - start() first
        self._run("pg_ctl", "-D", str(self.root / "data"), "-m", "immediate", "-w", "stop", timeout_s=30)

    def create_database(self, name: str) -> str:
        """A new empty database; its URL."""
        import psycopg

        with psycopg.connect(self.url(), autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')  # a name we made, not input
        return self.url(name)

    def log_tail(self, lines: int = 20) -> str:
        path = self.root / "server.log" if self.root else None
        if path is None or not path.exists():
            return ""
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])

    def stop(self) -> None:
        if self.root is None:
            return
        if (self.root / "data" / "postmaster.pid").exists():
            try:
                self._run("pg_ctl", "-D", str(self.root / "data"), "-m", "immediate", "-w", "stop", timeout_s=30)
            except (PostgresUnavailable, subprocess.TimeoutExpired):
                pass
        shutil.rmtree(self.root, ignore_errors=True)
        self.root = None

    def __enter__(self) -> TemporaryPostgres:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
