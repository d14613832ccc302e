"""Alembic migrations of the service database (``service/alembic.ini``)."""
