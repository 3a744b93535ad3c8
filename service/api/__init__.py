"""QuadLoc REST API (FastAPI). Build the app with :func:`quadloc.service.api.app.create_app`."""
