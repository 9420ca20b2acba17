"""Closing the loop (issue #5): residual analysis, candidate effects, forward selection."""
