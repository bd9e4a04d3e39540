"""``python -m clothlab``: the command line (:mod:`clothlab.cli`)."""

import sys

from clothlab.cli import main

if __name__ == "__main__":
    sys.exit(main())
