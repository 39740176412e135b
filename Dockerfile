# flexopt HTTP service. Build: docker build -t flexopt .   Run: docker run -p 8000:8000 -v flexopt-data:/data flexopt
# Jobs: SQLite file /data/jobs.sqlite and the finished cases of all jobs under /data/cases (the volume); set
# FLEXOPT_DATABASE_URL (or DATABASE_URL) to use PostgreSQL instead (install a driver, e.g. pg8000 or psycopg).
# Stopping: tini (PID 1) passes SIGTERM to the server, which ends requests within 3 s and its job processes
# within FLEXOPT_JOB_STOP_TIMEOUT (5 s; cases in progress are dropped and recomputed, finished ones are kept),
# inside Docker's default 10 s grace. To let cases in progress finish instead, raise both, e.g.
# FLEXOPT_JOB_STOP_TIMEOUT=60 with `docker run --stop-timeout 75` (compose: stop_grace_period: 75s).
FROM python:3.11-slim

# gcc: CasADi kernels are compiled to C on first use (model/kernels.py); without it they run uncompiled (slow).
RUN apt-get update \
    && apt-get install -y --no-install-recommends gcc libc6-dev tini \
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
# /ready: the job store can be written, the dispatcher runs, the worker pool is up (/health: the process answers)
HEALTHCHECK --interval=30s --timeout=8s --start-period=20s --retries=3 \
    CMD python -c "import urllib.request, sys; sys.exit(urllib.request.urlopen('http://127.0.0.1:8000/ready', timeout=7).status != 200)"

# tini (PID 1) forwards SIGTERM to the server and reaps orphans (job processes run in their own process groups,
# which the server stops itself; its own pool workers are shut down by the server)
STOPSIGNAL SIGTERM
ENTRYPOINT ["/usr/bin/tini", "--"]
CMD ["flexopt", "serve", "--host", "0.0.0.0", "--port", "8000"]
