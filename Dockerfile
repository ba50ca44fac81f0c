# motionx: one image for the API (`motionx serve`) and the workers (`motionx worker`).

# three.js for the web page, from npm (served by the API itself, no CDN)
FROM node:20-slim AS web
WORKDIR /web
COPY service/web/package.json service/web/package-lock.json ./
RUN npm ci --no-audit --no-fund --ignore-scripts

FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1

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

USER motionx
ENV MOTIONX_DATA_DIR=/home/motionx/data
EXPOSE 8000
CMD ["motionx", "serve", "--host", "0.0.0.0", "--port", "8000"]
