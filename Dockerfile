# The try-on service on a slim Python base with the software OpenGL libraries (Mesa llvmpipe).
FROM python:3.11-slim-bookworm
RUN apt-get update && apt-get install -y --no-install-recommends \
        libosmesa6 libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0 libgbm1 libglx-mesa0 make \
    && rm -rf /var/lib/apt/lists/*
WORKDIR /srv/tryon
COPY requirements.lock requirements-nodeps.lock ./
RUN pip install --no-cache-dir -r requirements.lock \
    && pip install --no-cache-dir --no-deps -r requirements-nodeps.lock
COPY pyproject.toml README.md ./
COPY engine engine
COPY app app
COPY web web
RUN pip install --no-cache-dir --no-deps -e . \
    && tryon body info default:female >/dev/null   # build and cache the default body at image build time
ENV TRYON_CACHE=/root/.cache/tryon
ENV TRYON_DATA=/srv/tryon/data
EXPOSE 8000
CMD ["python", "-m", "uvicorn", "--factory", "app.main:create_app", "--host", "0.0.0.0", "--port", "8000"]
