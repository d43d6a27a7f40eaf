"""The least-squares problem of a graph: batched factors with analytic Jacobians, the normal
equations on a sparsity pattern fixed once, the sparse Cholesky backends, selected inversion and
the directions that nothing measures."""
