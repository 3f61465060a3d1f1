"""Synthetic instances (being written)."""
