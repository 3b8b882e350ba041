"""The worker's soft time limit acts inside heyoka's loops (issue 19, item 13), with a real Celery worker.

Celery's soft limit is a signal whose Python handler runs only when control comes back to Python: a
job inside one long heyoka propagation (here a Lyapunov spectrum whose one QR interval is the whole
run) ran on to the hard limit and was killed. The job's progress callback now checks the soft limit
between the pieces of every long loop: the job ends at its soft limit, with the soft limit's message.

Needs Redis on 127.0.0.1:6379 and PostgreSQL (the README's test command starts them).
"""

from __future__ import annotations

import uuid

import httpx
import pytest

from tests.support import (
    TEST_REDIS_URL,
    free_port,
    poll_job,
    redis_available,
    start_api,
    start_worker,
    stop,
    wait_healthy,
)

pytestmark = pytest.mark.integration

BODY = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
        "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 20.0, "samples": 11}
#: A short run of the job under test: it compiles the variational equations and times this machine.
CALIBRATION_T = 2e4
#: Soft limit past the trajectory's phase, hard limit before the spectrum's one propagation ends (4 s
#: apart: a cooperative check comes every piece of 2,000 steps, well under a second even when loaded).
SOFT_S, HARD_S = 15, 19
#: Seconds the trajectory phase is made to take (the spectrum's propagation takes 5-10 times longer, per
#: unit of time, than the trajectory: past the hard limit; measured on this machine, not assumed).
TRAJECTORY_S = SOFT_S / 2
#: Hang guard (seconds) of each wait: a job ends at its soft limit, a compile takes seconds to a minute on a
#: quiet machine; never a result.
GUARD_S = 600.0


def one_long_propagation(t_final: float) -> dict:
    """The trajectory, then a Lyapunov spectrum whose one QR interval is the whole run."""
    return {**BODY, "t_final": t_final, "lyapunov": {"interval": t_final}}
LIMITS = {"NONHOLONOMIC_JOB_SOFT_TIME_LIMIT_S": str(SOFT_S), "NONHOLONOMIC_JOB_TIME_LIMIT_S": str(HARD_S),
          "NONHOLONOMIC_MAX_T_FINAL": "1e9"}


def test_the_soft_time_limit_ends_a_job_inside_a_long_heyoka_call(tmp_path):
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}: run the README's test command, which starts one")
    queue = f"soft-{uuid.uuid4().hex[:8]}"
    port = free_port()
    env = {"REDIS_URL": TEST_REDIS_URL, "NONHOLONOMIC_QUEUE": queue, **LIMITS}
    api = start_api(port, tmp_path / "api.log", env)
    worker = start_worker(TEST_REDIS_URL, queue, tmp_path / "worker.log", extra_env=LIMITS)
    base = f"http://127.0.0.1:{port}"
    try:
        with httpx.Client(base_url=base, timeout=10) as client:
            wait_healthy(base, timeout=GUARD_S)
            # compiles the variational equations first (LLVM, outside Python either way), and times them
            for _ in range(2):  # the second run is timed with everything compiled
                calibration = poll_job(client, client.post("/v1/jobs", json=one_long_propagation(CALIBRATION_T))
                                       .headers["location"], timeout=GUARD_S)
                assert calibration["status"] == "succeeded", calibration["error"]
            result = calibration["result"]
            trajectory_rate = result["integration"]["wall_time_s"] / CALIBRATION_T  # s per unit of t
            spectrum_rate = result["lyapunov"]["wall_time_s"] / CALIBRATION_T
            # the trajectory takes ~TRAJECTORY_S; and whatever noise the short timings carry, the job as a
            # whole outlasts the hard limit three times, so the soft limit always falls inside it
            t_final = max(TRAJECTORY_S / trajectory_rate, 3 * HARD_S / (trajectory_rate + spectrum_rate))
            print(f"t_final {t_final:.3g}: trajectory ~{trajectory_rate * t_final:.1f} s, "
                  f"spectrum ~{spectrum_rate * t_final:.0f} s")
            location = client.post("/v1/jobs", json=one_long_propagation(t_final)).headers["location"]
            view = poll_job(client, location, timeout=GUARD_S)
            assert view["status"] == "failed"
            assert view["error"] == {"type": "JobTimeout", "message": f"the job exceeded its time limit of {SOFT_S} s"}
            short = poll_job(client, client.post("/v1/jobs", json=BODY).headers["location"], timeout=GUARD_S)
            assert short["status"] == "succeeded"  # the same pool process goes on
    except Exception:
        for log in ("api.log", "worker.log"):
            print(f"--- {log}\n{(tmp_path / log).read_text()[-3000:]}")
        raise
    finally:
        stop(worker)
        stop(api)
