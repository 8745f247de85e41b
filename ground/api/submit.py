"""Validate and queue a processing job: the one place the API's `POST /flights/{id}/jobs` and the web
interface's forms go through (flight present and completely uploaded, parameters and files checked by
`job_kinds.check_job`, the job row written, then handed to the app's job runner)."""

from __future__ import annotations

from typing import Any, Protocol

from ground.api.job_kinds import check_job
from ground.store import Flight, Job, Store
from onboard.errors import InputError


class JobRefused(ValueError):
    """The job cannot be queued; `status` is the HTTP status (404 no flight, 409 upload incomplete, 422 bad
    parameters or missing files) and `detail` says why in words. Nothing was queued."""

    def __init__(self, status: int, detail: str) -> None:
        self.status = status
        self.detail = detail
        super().__init__(detail)


class JobSubmitter(Protocol):
    """What `app.state.jobs` offers the submission: run a job that already exists in the store."""

    def submit(self, job_id: str) -> None: ...


def queue_job(store: Store, jobs: JobSubmitter, flight_id: str, kind: str, params: dict[str, Any]) -> Job:
    """Check the job against the flight's completely uploaded files, store it `queued` and submit it.

    Raises `JobRefused` (nothing stored) when the flight is absent (404), not completely uploaded (409) or the
    kind's check refuses the parameters or files (422)."""
    with store.session() as s:
        flight = s.get(Flight, flight_id)
        if flight is None:
            raise JobRefused(404, f"no flight {flight_id}")
        if flight.status != "complete":
            raise JobRefused(409, "the flight's upload is not complete")
        try:
            check_job(kind, params, {f.name: f.role for f in flight.files if f.status == "complete"})
        except InputError as exc:
            raise JobRefused(422, f"{kind} job: {exc}") from exc
        job = Job(flight_id=flight_id, kind=kind, params=params)
        s.add(job)
        s.commit()
    jobs.submit(job.id)
    return job
