"""Settings of the ground API, validated once at start: data dir, database URL, token, size limits."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from onboard import validate
from onboard.errors import ConfigFileError

TOKEN_ENV = "DIRECTGEO_TOKEN"
MIN_TOKEN_CHARS = 16
#: where accepted jobs run: in child processes of the server, or on `ground worker`s through PostgreSQL
JOB_QUEUES = ("inprocess", "postgres")


@dataclass(frozen=True)
class ApiSettings:
    """Everything `create_app` needs. `token` is the shared bearer secret (never a default, never in code)."""

    data_dir: Path
    token: str
    database_url: str | None = None
    max_file_bytes: int = 8 * 1024**3
    max_flight_bytes: int = 64 * 1024**3
    max_chunk_bytes: int = 16 * 1024**2
    max_files_per_flight: int = 10_000
    job_workers: int = 1
    #: a job running longer than this (s) is stopped and failed
    job_timeout_s: float = 4 * 3600.0
    #: largest JSON request body (bytes): manifests of 10 000 files fit in ~2 MB
    max_json_bytes: int = 4 * 1024**2
    #: a web sign-in session ends this many seconds after sign-in (s)
    web_session_s: float = 12 * 3600.0
    #: largest outputs archive a worker may post for one job (bytes)
    max_output_bytes: int = 2 * 1024**3
    #: one of JOB_QUEUES: "inprocess" (default, no broker) or "postgres" (procrastinate; needs a PostgreSQL
    #: database_url; jobs run by `python -m ground worker`)
    job_queue: str = "inprocess"

    def __post_init__(self) -> None:
        if len(self.token) < MIN_TOKEN_CHARS:
            raise ConfigFileError(f"the API token must have at least {MIN_TOKEN_CHARS} characters")
        for name in ("max_file_bytes", "max_flight_bytes", "max_chunk_bytes", "max_files_per_flight",
                     "max_json_bytes", "max_output_bytes", "job_workers"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
                raise ConfigFileError(f"{name} {value!r}: must be a whole number > 0")
        if self.job_queue not in JOB_QUEUES:
            raise ConfigFileError(f"job queue {self.job_queue!r}: must be one of {', '.join(JOB_QUEUES)}")
        if self.job_queue == "postgres" and not (self.database_url or "").startswith(("postgresql", "postgres")):
            raise ConfigFileError("the postgres job queue needs a PostgreSQL database URL (--database-url or "
                                  "$DATABASE_URL, e.g. postgresql+psycopg://directgeo@db/directgeo)")
        try:
            validate.positive(self.job_timeout_s, name="job_timeout_s", unit=" s")
            validate.positive(self.web_session_s, name="web_session_s", unit=" s", maximum=30 * 86400.0)
        except ValueError as exc:
            raise ConfigFileError(str(exc)) from None

    @property
    def db_url(self) -> str:
        """`database_url`, or a SQLite file in the data directory."""
        return database_url(self.data_dir, self.database_url)

    @property
    def flights_dir(self) -> Path:
        """Where raw flight files live."""
        return self.data_dir / "flights"


def database_url(data_dir: Path, url: str | None = None) -> str:
    """The store's SQLAlchemy URL: `url` when given, else the SQLite file `directgeo.sqlite3` in `data_dir`."""
    return url or f"sqlite:///{data_dir / 'directgeo.sqlite3'}"


def load_token(token_file: str | Path | None = None, environ: dict[str, str] | None = None) -> str:
    """The API token: from `token_file` when given (first line), else from $DIRECTGEO_TOKEN; error when neither."""
    env = os.environ if environ is None else environ
    if token_file is not None:
        try:
            token = Path(token_file).read_text(encoding="utf-8").strip().splitlines()[0].strip()
        except (OSError, IndexError, UnicodeDecodeError) as exc:
            raise ConfigFileError(f"cannot read the token file {token_file}: {exc}") from exc
        return token
    token = env.get(TOKEN_ENV, "").strip()
    if not token:
        raise ConfigFileError(f"no API token: set ${TOKEN_ENV} or pass --token-file")
    return token
