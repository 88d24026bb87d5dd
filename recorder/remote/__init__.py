"""Remote recording: a station sends its session to a central recorder over HTTP or WebSocket.

`protocol` (the wire format, shared by both ends), `station` (the station's spool and sender),
`ingest` (the central store of remote sessions), `journal` (its journals and group commit: what
makes an acknowledgement durable), `routes` (the Starlette HTTP and WebSocket routes)."""
