"""Choosing what to fit: the parameters and the model (geometry, joint terms, a learned correction)
by how they predict data held out (cross-validation by poses, blocks, setups or sessions)."""
