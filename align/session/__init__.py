"""Whole sessions: ``session.toml`` -> every stage -> fusion -> JSON and HTML report.

Public API::

    load_session(folder) -> Session          (checked; InputError names the key at fault)
    run_session(session) -> SessionResult    (stage failures collected, not raised)
    result.to_dict() -> dict                 (the JSON contract of 'align run')
    run_batch(jobs, LocalPool(n) | DaskCluster(address)) -> summaries   (align run S1 S2 ...)
"""

from align.session.batch import (
    DaskCluster,
    LocalPool,
    SessionJob,
    batch_jobs,
    is_complete,
    run_batch,
    run_job,
)
from align.session.config import Session, load_session
from align.session.output import (
    session_document,
    session_outputs,
    truth_errors,
)
from align.session.run import SessionResult, StageError, observation_blocks, run_session

__all__ = ["DaskCluster", "LocalPool", "SessionJob", "batch_jobs", "is_complete", "run_batch",
           "run_job",
           "Session", "SessionResult", "StageError", "load_session", "observation_blocks",
           "run_session", "session_document",
           "session_outputs", "truth_errors"]
