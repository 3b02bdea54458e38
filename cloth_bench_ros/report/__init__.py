"""Layer 7: per-run report files and the sweep report document (tables, figures)."""
