"""vbl-robust."""
