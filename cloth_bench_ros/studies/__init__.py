"""Layer 6: the studies run over the node graph (run, sweep, stress, identify, rank)."""
