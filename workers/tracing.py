"""Optional OpenTelemetry traces spanning the API and the worker (off by default).

On when the standard variables ask for traces: ``OTEL_TRACES_EXPORTER`` (``otlp`` or ``console``; ``none``:
off) or ``OTEL_EXPORTER_OTLP_ENDPOINT`` / ``OTEL_EXPORTER_OTLP_TRACES_ENDPOINT`` (then ``otlp``), and the
packages of the ``otel`` extra are installed (``pip install nonholonomic[otel]``). ``OTEL_SERVICE_NAME``
names the service (default ``nonholonomic-api`` and ``nonholonomic-worker``); the OTLP exporter reads its
own ``OTEL_EXPORTER_OTLP_*`` variables.

The API's request span and the job's task span share one trace: the API's Celery instrumentation puts the
trace context in the task's headers, the worker's continues it. In a prefork worker each pool process sets
up its own provider (:func:`workers.celery_app._warm_up`, Celery's ``worker_process_init``): one made
before the fork would export from threads the child does not have, and the trace would split in two.
The log lines carry the ``trace_id`` while tracing is on (:class:`workers.logs.ContextFilter`).
"""

from __future__ import annotations

import logging
import os
from typing import Any

log = logging.getLogger(__name__)

_state = {"on": False}


def requested() -> bool:
    """Whether the ``OTEL_*`` variables ask for traces."""
    exporter = os.environ.get("OTEL_TRACES_EXPORTER", "").strip().lower()
    if exporter == "none" or os.environ.get("OTEL_SDK_DISABLED", "").lower() == "true":
        return False
    return bool(exporter or os.environ.get("OTEL_EXPORTER_OTLP_ENDPOINT")
                or os.environ.get("OTEL_EXPORTER_OTLP_TRACES_ENDPOINT"))


def enabled() -> bool:
    """Tracing is set up in this process."""
    return _state["on"]


def set_up(default_name: str) -> bool:
    """Set up the tracer provider of this process (once) and instrument Celery (its producer side in the
    API, its task side in a worker); False if traces are not asked for or the ``otel`` extra is missing."""
    if _state["on"]:
        return True
    if not requested():
        return False
    try:
        from opentelemetry import trace
        from opentelemetry.instrumentation.celery import CeleryInstrumentor
        from opentelemetry.sdk.resources import SERVICE_NAME, Resource
        from opentelemetry.sdk.trace import TracerProvider
        from opentelemetry.sdk.trace.export import BatchSpanProcessor, ConsoleSpanExporter, SimpleSpanProcessor
    except ImportError as exc:
        log.warning("OTEL_* variables ask for traces but the otel extra is not installed (%s): no traces", exc)
        return False
    exporter_name = os.environ.get("OTEL_TRACES_EXPORTER", "otlp").strip().lower() or "otlp"
    provider = TracerProvider(resource=Resource.create({SERVICE_NAME: os.environ.get("OTEL_SERVICE_NAME",
                                                                                     default_name)}))
    processor: Any
    if exporter_name == "console":
        processor = SimpleSpanProcessor(ConsoleSpanExporter())
    elif exporter_name == "otlp":
        from opentelemetry.exporter.otlp.proto.http.trace_exporter import OTLPSpanExporter

        processor = BatchSpanProcessor(OTLPSpanExporter())
    else:
        log.warning("OTEL_TRACES_EXPORTER=%s is not one of otlp, console, none: no traces", exporter_name)
        return False
    provider.add_span_processor(processor)
    trace.set_tracer_provider(provider)
    CeleryInstrumentor().instrument(tracer_provider=provider)
    _state["on"] = True
    log.info("traces on: %s exporter, service %s", exporter_name, provider.resource.attributes.get(SERVICE_NAME))
    return True


def instrument_app(app: Any) -> None:
    """The API's request spans (FastAPI's instrumentation), if tracing is set up."""
    if set_up("nonholonomic-api"):
        from opentelemetry.instrumentation.fastapi import FastAPIInstrumentor

        FastAPIInstrumentor.instrument_app(app, excluded_urls="health,metrics")


def current_trace_id() -> str | None:
    """The trace id of the current span (32 hex digits), while tracing is on."""
    if not _state["on"]:
        return None
    from opentelemetry import trace

    context = trace.get_current_span().get_span_context()
    return format(context.trace_id, "032x") if context.is_valid else None
