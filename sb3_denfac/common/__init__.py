"""Pieces shared by several algorithms: batch-norm MLPs, truncated Gaussian, inverting gradients, callbacks."""
