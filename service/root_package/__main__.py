"""``python -m microbearing``: the ``microbearing`` command line (:mod:`microbearing.service.cli`)."""

import sys

from microbearing.service.cli import main

sys.exit(main())
