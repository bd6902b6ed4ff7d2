"""What to trust of a fit: identifiability, statistics and diagnostics, the physicality verdict,
the data's checks, and the guard that keeps a fit no better than the geometric one from winning."""
