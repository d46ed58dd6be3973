"""Input and output: frame sources, the run writer (tracks.csv, run.json, particles.npz), atomic files and chunked
logs."""
