"""Alembic environment: runs on the connection handed over by ``service.storage.upgrade``.

From the command line:
``alembic -c service/alembic.ini -x url=sqlite:///orbitcal.sqlite upgrade head``.
"""

from __future__ import annotations

from alembic import context

from service.storage import Base, make_engine

config = context.config
target_metadata = Base.metadata


def run_migrations_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        context.configure(connection=connection, target_metadata=target_metadata)
        with context.begin_transaction():
            context.run_migrations()
        return
    url = context.get_x_argument(as_dictionary=True).get("url")
    if not url:
        raise SystemExit("pass the database with -x url=...")
    engine = make_engine(url)
    with engine.connect() as conn:
        context.configure(connection=conn, target_metadata=target_metadata)
        with context.begin_transaction():
            context.run_migrations()
        conn.commit()


run_migrations_online()
