"""Reference solutions that share no code with jsss, fitting or measure (NumPy only)."""
