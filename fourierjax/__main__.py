"""`python -m fourierjax` runs the command line."""

from fourierjax.cli import console

console()
