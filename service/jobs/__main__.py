"""``python -m flexopt.service.jobs run JOB_ID ATTEMPT``: a job process (started by the dispatcher)."""

import sys

from .run import main

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
