"""Alembic revision scripts (a package so that non-editable installs ship them)."""
