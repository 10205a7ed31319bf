"""`python -m fourierjax` runs the command line."""

import sys

from fourierjax.cli import main

sys.exit(main())
