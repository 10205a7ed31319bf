"""Differentiable JAX library for stylized human motion."""

__version__ = "0.1.0"
