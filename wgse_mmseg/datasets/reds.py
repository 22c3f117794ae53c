"""REDS spike reconstruction datasets (issue 6)."""
