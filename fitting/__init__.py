"""fitting: iterative fits of jsss models to data (Gaussian sums, medium parameters)."""
