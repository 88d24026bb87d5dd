"""The ``vascsim`` command line: one entry point, a module per command group.

User errors (any :class:`sim.errors.VascsimError`) print one line on stderr and exit with status
1; ``--help`` on every command explains its options. Each command is registered here, explicitly,
so where a command lives is this list; ``vascsim serve`` is registered the same way by the console
script (:mod:`dashboard.cli`), so this package never imports the web stack.
"""

from __future__ import annotations

from sessions.cli import (
    benchmark,
    calibrate,
    demo,
    devices,
    export,
    import_bundle,
    import_jigsaws,
    import_video,
    indentation,
    instruments,
    keys,
    lrs,
    markers,
    participants,
    ratings,
    recover,
    replay,
    report,
    run,
    score,
    sessions,
    standards,
    station,
    studies,
    tasks,
    users,
)
from sessions.cli.base import main, open_catalog, user_errors

__all__ = ["main", "open_catalog", "user_errors"]

for command in (
    demo.demo,
    run.run,
    station.station,
    sessions.sessions,
    score.score,
    report.report,
    replay.replay,
    studies.studies,
    standards.standards,
    participants.participants,
    ratings.ratings,
    tasks.tasks,
    indentation.indentation,
    devices.devices,
    recover.recover,
    export.export_bundle,
    keys.keys,
    import_bundle.import_bundle_command,
    calibrate.calibrate,
    markers.markers,
    instruments.instruments,
    import_video.import_video,
    import_jigsaws.import_jigsaws,
    users.users,
    benchmark.benchmark,
    lrs.lrs,
):
    main.add_command(command)
