"""Private implementation of `fourierjax.fourier` (import from there)."""
