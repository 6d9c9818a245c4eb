# syntax=docker/dockerfile:1
# A STAND-IN for the eclipse/zenoh router image, for machines that cannot pull it (no image
# registry reachable): docker/router_standin.py, a Python zenoh session in router mode that
# takes zenohd's arguments (-c FILE, --cfg KEY:VALUE) and applies the same TLS, passwords and
# access control (the same Rust library underneath), on the same Python base as the rhbl image
# and the eclipse-zenoh version pinned in docker/requirements.lock. `make compose-test` builds
# it as rhbl-router-standin:<that version>; it is never tagged eclipse/zenoh.
#   docker build -f docker/router-standin.Dockerfile -t rhbl-router-standin:1.10.2 .
ARG PYTHON_IMAGE=python:3.11-slim-bookworm
FROM ${PYTHON_IMAGE}
LABEL org.opencontainers.image.title="rhbl-router-standin" \
      org.opencontainers.image.description="Stand-in for the eclipse/zenoh router image: a Python zenoh session in router mode (not zenohd)"
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1
COPY docker/requirements.lock /tmp/requirements.lock
# the one package it needs, at the version the lock file pins (binary wheel only)
RUN pip install --only-binary=:all: -c /tmp/requirements.lock eclipse-zenoh \
 && rm /tmp/requirements.lock
COPY --chmod=0644 docker/router_standin.py /usr/local/lib/rhbl/router_standin.py
USER 10001:10001
# like eclipse/zenoh: no health check (the router's health is that its clients connect)
ENTRYPOINT ["python", "/usr/local/lib/rhbl/router_standin.py"]
CMD ["-c", "/etc/zenoh/router.json5"]
