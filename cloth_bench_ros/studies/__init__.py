"""Layer 6: the studies run over the node graph (run, sweep, settings sweep, stress, hil)."""
