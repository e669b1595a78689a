# The one image of Aerobase: `aerobase server`, the daemons and the simulated world.
#   docker build -t aerobase .
# Multi-stage: the build stage compiles wheels (gcc for the packages that need it); the runtime
# stage has no compiler and runs as an unprivileged user. Nothing secret is baked in: every
# setting comes from the environment (docker-compose.yml reads .env; see .env.example).

# the base: CPython 3.11 on Debian bookworm; a site without Docker Hub passes its own
# (tests/deploy/test_images.py builds one with debootstrap)
ARG PYTHON_IMAGE=python:3.11-slim-bookworm
FROM ${PYTHON_IMAGE} AS build
RUN apt-get update \
    && apt-get install -y --no-install-recommends gcc libc6-dev \
    && rm -rf /var/lib/apt/lists/*
ENV PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1
RUN python -m venv /opt/venv
WORKDIR /app
# dependencies first, so a source change does not reinstall them
COPY pyproject.toml README.md ./
RUN mkdir -p aerobase && touch aerobase/__init__.py \
    && /opt/venv/bin/pip install . \
    && /opt/venv/bin/pip uninstall -y aerobase
COPY aerobase aerobase
COPY server server
COPY migrations migrations
COPY protocol protocol
COPY assetlink assetlink
COPY asynckit asynckit
COPY base_station base_station
COPY asset_agent asset_agent
COPY sim sim
COPY bench bench
# editable: the migrations folder stays beside server/ where server/migrate.py looks for it
RUN /opt/venv/bin/pip install --no-deps -e .

FROM ${PYTHON_IMAGE} AS runtime
# state/: the daemons' link state files; a named volume mounted there (compose's demo-state)
# takes the folder's owner from the image, so the unprivileged user can write it
RUN groupadd --system aerobase \
    && useradd --system --gid aerobase --home-dir /var/lib/aerobase --create-home aerobase \
    && install -d -o aerobase -g aerobase -m 0700 /var/lib/aerobase/state
COPY --from=build /opt/venv /opt/venv
COPY --from=build /app /app
ENV PATH=/opt/venv/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    AEROBASE_HOST=0.0.0.0 \
    AEROBASE_PORT=8000 \
    AEROBASE_LOG_FORMAT=json
WORKDIR /var/lib/aerobase
USER aerobase
EXPOSE 8000
HEALTHCHECK --interval=10s --timeout=3s --start-period=20s --retries=3 \
    CMD ["python", "-c", "import sys, urllib.request; sys.exit(urllib.request.urlopen('http://127.0.0.1:8000/api/health', timeout=2).status != 200)"]
ENTRYPOINT ["aerobase"]
CMD ["server"]
