"""Runs ralph's LRS (its own FastAPI app, file-system backend) on 127.0.0.1 for the xAPI tests.

Started with .venv-lrs's Python (scripts/bootstrap installs ralph there: its pins conflict with
ours). ralph 5.1.0's file-system backend writes each POST with operation CREATE, so only the first
POST to a store succeeds and every later one fails with "already exists" (a 500); the backend's own
APPEND operation is what an LRS needs, and is made its default here. Everything else is ralph's.

    .venv-lrs/bin/python tests/lrs_server.py PORT
with RALPH_APP_DIR (holding auth.json), RALPH_RUNSERVER_BACKEND=fs and
RALPH_BACKENDS__LRS__FS__DEFAULT_DIRECTORY_PATH set.
"""

import sys

import uvicorn
from ralph.backends.data.base import BaseOperationType
from ralph.backends.data.fs import FSDataBackend

FSDataBackend.default_operation_type = BaseOperationType.APPEND
uvicorn.run("ralph.api:app", host="127.0.0.1", port=int(sys.argv[1]), log_level="warning")
