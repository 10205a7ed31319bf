"""The clip-fitting pipeline behind `fourierjax.motion` (private modules)."""
