"""Data files shipped with the service (see README.md)."""
