"""Closing the loop: residual analysis, candidate effects, forward selection."""
