"""Log lines an operator can follow: one JSON object per line, with the request id and the job id.

The API takes a request's id from its ``X-Request-ID`` header (or makes one) and echoes it in the answer
(:class:`service.request_id.RequestId`); the id goes with the job's task in its headers
(``request_id``: :func:`workers.celery_app._carry_request_id`), so the worker's lines of that job carry it
too: one id finds a request, its job and the worker's lines. ``NONHOLONOMIC_LOG_FORMAT=text`` gives plain
lines instead (with the ids in brackets).
"""

from __future__ import annotations

import logging
import re
import sys
import uuid
from contextvars import ContextVar

from pythonjsonlogger.json import JsonFormatter

from workers import tracing

#: The request being answered, or whose job runs; the job (or ensemble chunk's task) running.
REQUEST_ID: ContextVar[str | None] = ContextVar("request_id", default=None)
JOB_ID: ContextVar[str | None] = ContextVar("job_id", default=None)
#: The header a request id comes in and goes out in; the task header that carries it to the worker.
HEADER = "X-Request-ID"
TASK_HEADER = "request_id"
#: An id a client may choose: 1-128 characters of letters, digits and ``._:-@/+=`` (else one is made).
_VALID_ID = re.compile(r"[A-Za-z0-9._:@/+=-]{1,128}")
_FIELDS = "%(levelname)s %(name)s %(message)s"
_RENAMED = {"levelname": "level", "name": "logger"}
#: The loggers of this service's own packages: their INFO lines are kept (the root logger's level stays).
OWN_LOGGERS = ("service", "workers", "store")


def request_id_from(header: str | None) -> str:
    """The client's id if it is a valid one, else a new one (32 hex digits)."""
    if header and _VALID_ID.fullmatch(header):
        return header
    return uuid.uuid4().hex


class ContextFilter(logging.Filter):
    """Adds ``request_id`` and ``job_id`` (this context's) to every record; uvicorn's access lines also
    get ``method``, ``path`` and ``status`` as fields."""

    def filter(self, record: logging.LogRecord) -> bool:
        if not hasattr(record, "request_id"):
            record.request_id = REQUEST_ID.get()
        if not hasattr(record, "job_id"):
            record.job_id = JOB_ID.get()
        if tracing.enabled() and not hasattr(record, "trace_id"):
            record.trace_id = tracing.current_trace_id()
        record.__dict__.pop("color_message", None)  # uvicorn's copy of the message with terminal colours
        if record.name == "uvicorn.access" and isinstance(record.args, tuple) and len(record.args) == 5:
            _, record.method, record.path, _, record.status = record.args
        return True


def formatter(log_format: str) -> logging.Formatter:
    """JSON lines (``time``, ``level``, ``logger``, ``message``, ``request_id``, ``job_id``, and any
    ``extra``) or plain text."""
    if log_format == "json":
        return JsonFormatter(_FIELDS, rename_fields=_RENAMED, timestamp="time", json_ensure_ascii=False)
    return _TextFormatter("%(asctime)s %(levelname)s %(name)s %(ids)s%(message)s")


class _TextFormatter(logging.Formatter):
    """Plain lines, the request and job ids in brackets where there are any."""

    def format(self, record: logging.LogRecord) -> str:
        ids = [f"{name}={value}" for name in ("request_id", "job_id")
               if (value := getattr(record, name, None))]
        record.ids = f"[{' '.join(ids)}] " if ids else ""
        return super().format(record)


def use_format(handlers: list[logging.Handler], log_format: str) -> None:
    """Give ``handlers`` the format and the context filter (once each)."""
    chosen = formatter(log_format)
    for handler in handlers:
        handler.setFormatter(chosen)
        if not any(isinstance(f, ContextFilter) for f in handler.filters):
            handler.addFilter(ContextFilter())


def configure_api(log_format: str) -> None:
    """The API's lines: uvicorn's (its error and access loggers') and the service's own (a handler on the
    root logger, added unless it has one already, e.g. under pytest)."""
    root = logging.getLogger()
    if not root.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.set_name("nonholonomic")
        root.addHandler(handler)
        for name in OWN_LOGGERS:
            logging.getLogger(name).setLevel(logging.INFO)
    ours = [h for h in root.handlers if h.get_name() == "nonholonomic"]
    for name in ("uvicorn", "uvicorn.error", "uvicorn.access"):
        ours.extend(logging.getLogger(name).handlers)
    use_format(ours, log_format)
