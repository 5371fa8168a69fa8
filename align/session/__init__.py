"""Whole sessions: ``session.toml`` -> every stage -> fusion -> JSON and HTML report.

Public API::

    load_session(folder) -> Session          (checked; InputError names the key at fault)
    run_session(session) -> SessionResult    (stage failures collected, not raised)
    result_json(result) -> dict              (the JSON contract of 'align run')
"""

from align.session.config import Session, load_session
from align.session.output import (
    platform_calibration,
    result_json,
    session_document,
    session_outputs,
    truth_errors,
)
from align.session.run import SessionResult, StageError, observation_blocks, run_session

__all__ = ["Session", "SessionResult", "StageError", "load_session", "observation_blocks",
           "platform_calibration", "result_json", "run_session", "session_document",
           "session_outputs", "truth_errors"]
