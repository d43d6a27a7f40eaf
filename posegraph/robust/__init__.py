"""Robust estimation: IRLS kernels, the robust spec, graduated non-convexity (GNC) with its
local search, and priors solved as edges from a held world node."""
