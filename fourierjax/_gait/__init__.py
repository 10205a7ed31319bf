"""Private modules behind `fourierjax.gait` (Unuma 1995 §3.1 step constraints)."""
