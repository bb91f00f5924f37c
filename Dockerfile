# dexroll planning service. The build runs the same Makefile targets as the README's
# quickstart (`make run` = `make install` + `dexroll serve`), which CI exercises.
FROM python:3.11-slim

# The service listens on all of the container's interfaces; publish it on the host's
# loopback (docker run -p 127.0.0.1:8000:8000 ...). Without DEXROLL_API_KEYS (or
# DEXROLL_API_KEYS_FILE) it serves anyone who reaches the port, and says so loudly in its
# log at start; the Host allow-list (DEXROLL_ALLOWED_HOSTS) defaults to the loopback names.
ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    DEXROLL_HOST=0.0.0.0 \
    DEXROLL_PORT=8000 \
    DEXROLL_DATA_DIR=/data

RUN apt-get update \
    && apt-get install -y --no-install-recommends make \
    && rm -rf /var/lib/apt/lists/* \
    && useradd --create-home --uid 10001 dexroll \
    && mkdir -p /app /data && chown dexroll:dexroll /app /data

USER dexroll
WORKDIR /app

# dependencies in their own layer: only the files that list them
COPY --chown=dexroll:dexroll Makefile pyproject.toml ./
COPY --chown=dexroll:dexroll clients/python/pyproject.toml clients/python/pyproject.toml
COPY --chown=dexroll:dexroll tools/requirements.py tools/requirements.py
RUN make deps

# the project itself
COPY --chown=dexroll:dexroll . .
RUN make install

VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=30s --timeout=5s --start-period=60s --retries=3 \
    CMD ["/app/.venv/bin/python", "-c", "import os, urllib.request; urllib.request.urlopen(f\"http://127.0.0.1:{os.environ['DEXROLL_PORT']}/healthz\", timeout=4)"]
# `make run` without its install step (done above): the service on its embedded defaults
CMD ["/app/.venv/bin/dexroll", "serve"]
