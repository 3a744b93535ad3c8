"""QuadLoc REST API (FastAPI). Build the app with :func:`service.api.app.create_app`."""
