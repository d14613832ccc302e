"""Model coefficient files (see README.md here for provenance)."""
