"""Private implementation of `fourierjax.rotations` (the public face re-exports it)."""
