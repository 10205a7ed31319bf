"""Fuzz and fault suite: mutated BVH and model files, CLI arguments, gradients at singular points."""
