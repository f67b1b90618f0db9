"""``python -m visla_edu`` runs the command line (see :mod:`visla_edu.cli`)."""

import sys

from visla_edu.cli import main

sys.exit(main())
