"""Celery worker: the app is built from the settings by :func:`worker.app.create_celery`."""
