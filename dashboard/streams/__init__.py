"""A session's streams as the dashboard serves them: a running station's journals as server-sent
events (`live`), a recorded session's plotted signals and files (`signals`), and replay videos
rendered on request, one at a time (`replay_jobs`)."""
