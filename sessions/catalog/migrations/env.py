"""Alembic environment: the connection is handed in by sessions.catalog (no alembic.ini needed)."""

from alembic import context

from sessions.catalog.models import Base

connection = context.config.attributes["connection"]
context.configure(connection=connection, target_metadata=Base.metadata, render_as_batch=True)
with context.begin_transaction():
    context.run_migrations()
