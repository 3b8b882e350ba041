"""A running job rides out a Redis outage (issue 19, item 9), with a real worker, a Redis of the test's
own (stopped and started again empty; the machine's Redis is not touched) and PostgreSQL.

Progress goes to Celery's result backend (Redis) and is best-effort: a write that fails is skipped
and the job goes on; its end is written to the job store (PostgreSQL). Before, a progress write
retried for ~19 s and then raised ``ConnectionError``, and the job ended ``failed``.
"""

from __future__ import annotations

import time

import pytest

from tests.integration.test_durability import BODY, QueueStack, _redis_server
from tests.support import drop_database, free_port, fresh_database_url, poll_job, redis_available, wait_until

pytestmark = pytest.mark.integration

#: Several seconds of integration with progress reports all along.
LONG = {**BODY, "t_final": 2e6}
#: Longer than Celery's retries of one progress write (20 tries a second apart): Redis stays away at least
#: this long, and until the worker has logged a progress write it skipped.
OUTAGE_S = 25.0
#: Hang guard (seconds) of each wait: far above the seconds a quiet machine needs, never a result.
GUARD_S = 300.0


def _skipped_writes(tmp_path) -> int:
    """Progress writes the worker skipped, as its log says (whole logs: QueueStack.logs keeps their ends)."""
    return sum(p.read_text().count("not written") for p in tmp_path.glob("*.log"))


def test_a_running_job_rides_out_a_redis_outage_with_the_same_numbers(tmp_path):
    redis_port = free_port()
    redis_url = f"redis://127.0.0.1:{redis_port}/0"
    server = _redis_server(redis_port, tmp_path / "00-redis.log")
    database = fresh_database_url()
    stack = QueueStack(tmp_path, redis_url, database)
    try:
        wait_until(lambda: redis_available(redis_url), 30, "the test's Redis")
        stack.start_api()
        stack.start_worker()
        reference = poll_job(stack.client, stack.client.post("/v1/jobs", json=LONG).headers["location"],
                             timeout=GUARD_S)
        assert reference["status"] == "succeeded", reference["error"]

        location = stack.client.post("/v1/jobs", json=LONG).headers["location"]
        wait_until(lambda: stack.client.get(location).json()["progress"] >= 0.02, GUARD_S,
                   "the job to run (a hang guard)")
        skipped = _skipped_writes(tmp_path)
        server.kill()  # Redis gone mid-job, with every progress and message
        server.wait(10)
        gone = time.monotonic()
        # the running job's next progress write fails: skipped and logged by the worker, the job goes on
        wait_until(lambda: _skipped_writes(tmp_path) > skipped, GUARD_S,
                   "the worker to log a progress write it skipped (a hang guard)")
        time.sleep(max(0.0, OUTAGE_S - (time.monotonic() - gone)))  # the outage's length, not a bound
        server = _redis_server(redis_port, tmp_path / "00-redis-2.log")  # back, empty
        wait_until(lambda: redis_available(redis_url), 30, "the test's Redis again")

        view = poll_job(stack.client, location, timeout=GUARD_S)
        assert view["status"] == "succeeded", view["error"]
        assert view["result"]["final_state"] == reference["result"]["final_state"]
        assert view["result"]["integrals"] == reference["result"]["integrals"]
        after = poll_job(stack.client, stack.client.post("/v1/jobs", json=BODY).headers["location"],
                         timeout=GUARD_S)
        assert after["status"] == "succeeded", after["error"]  # the worker took up the queue again
    except Exception:
        print(stack.logs())
        raise
    finally:
        stack.stop()
        server.kill()
        drop_database(database)
