"""g2o I/O (being written)."""
