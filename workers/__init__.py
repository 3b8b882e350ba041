"""Job execution: the job function (:mod:`workers.jobs`, shared by Celery and embedded mode), the
Celery app (:mod:`workers.celery_app`), its task (:mod:`workers.tasks`) and the Redis job registry."""
