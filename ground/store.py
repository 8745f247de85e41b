"""Flight store: SQLAlchemy models (flights, files, upload sessions, jobs, API tokens, web sign-in sessions) and
small helpers.

SQLite file by default (`sqlite:///<data_dir>/directgeo.sqlite3`), any SQLAlchemy URL (PostgreSQL) through
`DATABASE_URL`. Raw files live on disk under `<data_dir>/flights/<flight id>/`; the database holds what was
promised (manifest: names, sizes, SHA-256) and what was received.
"""

from __future__ import annotations

import datetime as dt
import uuid
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    DateTime,
    ForeignKey,
    Integer,
    String,
    Text,
    UniqueConstraint,
    create_engine,
    inspect,
    text,
)
from sqlalchemy.engine import Engine
from sqlalchemy.orm import DeclarativeBase, Mapped, Session, mapped_column, relationship, sessionmaker


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def new_id() -> str:
    """A random 32-hex-digit identifier (no ordering information leaks, no collisions in practice)."""
    return uuid.uuid4().hex


class Base(DeclarativeBase):
    """Declarative base of the store's tables."""


class Flight(Base):
    """One flight: its name (from the onboard manifest), state and the manifest as received."""

    __tablename__ = "flights"

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    name: Mapped[str] = mapped_column(String(255), unique=True, index=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=_now)
    status: Mapped[str] = mapped_column(String(32), default="uploading")  # uploading | complete
    manifest: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    #: id of the API token that created the flight (None: the bootstrap token, or a flight older than tokens);
    #: a drone token may only touch the flights it created
    created_by: Mapped[str | None] = mapped_column(String(32), nullable=True)
    #: that token (its name: the drone's, for a drone's upload); no foreign key: tokens are revoked, never deleted,
    #: and flights of older databases have none
    creator: Mapped[ApiToken | None] = relationship(primaryjoin="foreign(Flight.created_by) == ApiToken.id",
                                                    viewonly=True, lazy="joined")
    files: Mapped[list[FlightFile]] = relationship(back_populates="flight", cascade="all, delete-orphan",
                                                   order_by="FlightFile.name")
    jobs: Mapped[list[Job]] = relationship(back_populates="flight", cascade="all, delete-orphan",
                                           order_by="Job.created_at")


class FlightFile(Base):
    """A file promised by the manifest: expected size and SHA-256, bytes received so far, final state."""

    __tablename__ = "flight_files"
    __table_args__ = (UniqueConstraint("flight_id", "name"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    flight_id: Mapped[str] = mapped_column(ForeignKey("flights.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(255))
    role: Mapped[str | None] = mapped_column(String(32), nullable=True)
    size: Mapped[int] = mapped_column(BigInteger)
    sha256: Mapped[str] = mapped_column(String(64))
    received: Mapped[int] = mapped_column(BigInteger, default=0)
    status: Mapped[str] = mapped_column(String(16), default="pending")  # pending | partial | complete
    flight: Mapped[Flight] = relationship(back_populates="files")
    sessions: Mapped[list[UploadSession]] = relationship(back_populates="file", cascade="all, delete-orphan")


class UploadSession(Base):
    """One client's run of chunk uploads to a file (a resumed upload opens a new session at its offset)."""

    __tablename__ = "upload_sessions"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    file_id: Mapped[int] = mapped_column(ForeignKey("flight_files.id", ondelete="CASCADE"), index=True)
    client: Mapped[str] = mapped_column(String(64), default="")
    start_offset: Mapped[int] = mapped_column(BigInteger, default=0)
    bytes_received: Mapped[int] = mapped_column(BigInteger, default=0)
    chunks: Mapped[int] = mapped_column(Integer, default=0)
    rejected_chunks: Mapped[int] = mapped_column(Integer, default=0)
    started_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=_now)
    updated_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=_now)
    file: Mapped[FlightFile] = relationship(back_populates="sessions")


class Job(Base):
    """A processing job on a flight (`adjust`, `rtk`) and its status: queued | running | done | failed."""

    __tablename__ = "jobs"

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    flight_id: Mapped[str] = mapped_column(ForeignKey("flights.id", ondelete="CASCADE"), index=True)
    kind: Mapped[str] = mapped_column(String(16))
    status: Mapped[str] = mapped_column(String(16), default="queued")
    params: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    message: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=_now)
    started_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    finished_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    flight: Mapped[Flight] = relationship(back_populates="jobs")


class ApiToken(Base):
    """A bearer token with a role. Only its SHA-256 is kept: the clear token is shown once, at creation.

    A plain SHA-256 (no salt, no slow KDF) is the right hash here: tokens are 32 random bytes from `secrets`
    (256 bits), so there is no dictionary to try and a brute force of the digest is out of reach whatever its
    speed; a slow KDF would only cost time on every request, and an unsalted digest can be looked up directly.
    """

    __tablename__ = "api_tokens"

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    name: Mapped[str] = mapped_column(String(100), unique=True, index=True)
    role: Mapped[str] = mapped_column(String(16))  # drone | engineer | admin | worker (ground.api.auth.Role)
    token_sha256: Mapped[str] = mapped_column(String(64), unique=True, index=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=_now)
    revoked_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    last_used_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)


class WebSession(Base):
    """A signed-in browser of the web interface: the SHA-256 of the session cookie's random id (the id itself is
    never stored), the CSRF token its forms carry, who signed in (the user token's id, name and role) and when
    the session ends (UTC)."""

    __tablename__ = "web_sessions"

    id_sha256: Mapped[str] = mapped_column(String(64), primary_key=True)
    csrf_token: Mapped[str] = mapped_column(String(64))
    #: the `api_tokens` id; None for the bootstrap admin token of the settings
    token_id: Mapped[str | None] = mapped_column(String(32), index=True, nullable=True)
    name: Mapped[str] = mapped_column(String(255), default="")
    role: Mapped[str] = mapped_column(String(16))
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=_now)
    expires_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), index=True)


def _add_missing_columns(engine: Engine) -> list[str]:
    """Add the nullable columns a newer model has and an existing database lacks (e.g. `flights.created_by`);
    returns the `table.column` names added. The schema only ever grows by nullable columns, so this is the
    whole migration."""
    insp = inspect(engine)
    added: list[str] = []
    with engine.begin() as conn:
        for table in Base.metadata.sorted_tables:
            if not insp.has_table(table.name):
                continue
            present = {c["name"] for c in insp.get_columns(table.name)}
            for col in table.columns:
                if col.name in present:
                    continue
                if not col.nullable:
                    raise RuntimeError(f"the database's table {table.name} lacks the non-null column {col.name}")
                ddl = col.type.compile(dialect=engine.dialect)
                conn.execute(text(f'ALTER TABLE {table.name} ADD COLUMN {col.name} {ddl}'))
                added.append(f"{table.name}.{col.name}")
    return added


class Store:
    """Engine + session factory; `create_all` on open, plus the nullable columns an older database lacks (the
    schema is small and additive)."""

    def __init__(self, database_url: str) -> None:
        kwargs: dict[str, Any] = {}
        if database_url.startswith("sqlite"):
            # uvicorn serves sync endpoints from a thread pool and jobs run in a worker thread
            kwargs["connect_args"] = {"check_same_thread": False, "timeout": 30}
        else:  # a database server restarted: pooled connections are tested (one round trip) before use
            kwargs["pool_pre_ping"] = True
        self.engine: Engine = create_engine(database_url, **kwargs)
        _add_missing_columns(self.engine)
        Base.metadata.create_all(self.engine)
        self.sessions = sessionmaker(self.engine, expire_on_commit=False)

    def session(self) -> Session:
        """A new ORM session (use as a context manager)."""
        return self.sessions()

    def close(self) -> None:
        """Dispose of the connection pool."""
        self.engine.dispose()
