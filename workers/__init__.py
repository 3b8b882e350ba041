"""Job execution: the job function (:mod:`workers.jobs`, shared by Celery and embedded mode), the
Celery app (:mod:`workers.celery_app`), its tasks (:mod:`workers.tasks`), the workers' job store and
the broker's epoch (:mod:`workers.job_store`), heartbeats and redelivery."""
