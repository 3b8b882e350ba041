# One image for the API and the worker (docker-compose.yml chooses the command).
FROM python:3.11-slim
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1
# The commit results name in integration.project (the image has no .git): --build-arg GIT_COMMIT=$(git rev-parse HEAD)
ARG GIT_COMMIT=
ENV NONHOLONOMIC_GIT_COMMIT=${GIT_COMMIT}
WORKDIR /app
COPY pyproject.toml README.md ./
COPY nonholonomic ./nonholonomic
COPY schemas ./schemas
COPY service ./service
COPY workers ./workers
COPY client ./client
COPY store ./store
# the otel extra: OpenTelemetry traces, off unless the OTEL_* variables ask for them (docs/operating.md)
RUN pip install --no-cache-dir ".[otel]" && useradd --create-home app
USER app
EXPOSE 8000
CMD ["uvicorn", "service.main:app", "--host", "0.0.0.0", "--port", "8000"]
