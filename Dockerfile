# motionx: one image for the API (`motionx serve`) and the workers (`motionx worker`).

# three.js for the web page and Swagger UI for /docs, from npm (served by the API itself, no CDN)
FROM node:20-slim AS web
WORKDIR /web
COPY service/web/package.json service/web/package-lock.json ./
RUN npm ci --no-audit --no-fund --ignore-scripts

FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1

# a C compiler: each character's NLP derivatives are compiled once to machine code
# (solver.spacetime.compiled; 1.3-1.6x faster HalfBoy solves), cached under ~/.cache/motionx/compiled
RUN apt-get update -qq && apt-get install -y -qq --no-install-recommends gcc libc6-dev \
    && rm -rf /var/lib/apt/lists/*
RUN useradd --create-home --uid 10001 motionx
WORKDIR /app

COPY pyproject.toml README.md alembic.ini ./
COPY solver ./solver
COPY mjcf ./mjcf
COPY service ./service
COPY worker ./worker
COPY --from=web /web/node_modules/three ./service/web/node_modules/three
COPY --from=web /web/node_modules/swagger-ui-dist ./service/web/node_modules/swagger-ui-dist
RUN pip install .

# the demo's walk (`motionx demo` in the image) with its origin and license notices; the
# installed package finds trials through MOTIONX_DATA (the other trials of data/ are for the
# tests and benchmarks, which run from a checkout)
COPY data/README.md ./data/README.md
COPY data/deepmimic_humanoid3d_walk ./data/deepmimic_humanoid3d_walk
ENV MOTIONX_DATA=/app/data

# the service's state (SQLite database, stored motions) when no DATABASE_URL is given
RUN mkdir -p /var/lib/motionx && chown motionx /var/lib/motionx
USER motionx
ENV MOTIONX_DATA_DIR=/var/lib/motionx
EXPOSE 8000
CMD ["motionx", "serve", "--host", "0.0.0.0", "--port", "8000"]
