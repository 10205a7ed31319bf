"""Private implementation of `fourierjax.style`; import the public names from there."""
