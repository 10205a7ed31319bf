"""Expressive stance (Neff & Fiume 2004): 48-DOF skeleton, lower-body IK, balance, shape solver."""
