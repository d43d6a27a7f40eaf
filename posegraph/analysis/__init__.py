"""What a solved graph tells: marginal covariances and the graph doctor."""
