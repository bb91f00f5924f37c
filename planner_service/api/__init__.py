"""The HTTP API (FastAPI): :func:`.app.create_app`, the routes (:mod:`.routes`) and what
they depend on (:mod:`.deps`)."""
