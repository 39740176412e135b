# flexopt HTTP service. Build: docker build -t flexopt .   Run: docker run -p 8000:8000 -v flexopt-data:/data flexopt
# Jobs: SQLite file /data/jobs.sqlite and each job's finished cases under /data/jobs (the volume); set
# FLEXOPT_DATABASE_URL (or DATABASE_URL) to use PostgreSQL instead (install a driver, e.g. psycopg).
FROM python:3.11-slim

# gcc: CasADi kernels are compiled to C on first use (model/kernels.py); without it they run uncompiled (slow).
RUN apt-get update \
    && apt-get install -y --no-install-recommends gcc libc6-dev \
    && rm -rf /var/lib/apt/lists/*

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    FLEXOPT_CACHE_DIR=/data/kernels \
    FLEXOPT_DATA_DIR=/data \
    MPLCONFIGDIR=/tmp/matplotlib

WORKDIR /app
COPY pyproject.toml README.md LICENSE ./
COPY model ./model
COPY optim ./optim
COPY service ./service
RUN pip install ".[service,cluster]"

RUN useradd --create-home --uid 10001 flexopt \
    && mkdir -p /data/kernels \
    && chown -R flexopt:flexopt /data
USER flexopt
VOLUME ["/data"]

EXPOSE 8000
HEALTHCHECK --interval=30s --timeout=5s --start-period=20s --retries=3 \
    CMD python -c "import urllib.request, sys; sys.exit(urllib.request.urlopen('http://127.0.0.1:8000/health', timeout=4).status != 200)"

CMD ["flexopt", "serve", "--host", "0.0.0.0", "--port", "8000"]
