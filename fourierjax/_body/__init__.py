"""Private implementation of `fourierjax.body`: name tables, the map and its inference."""
