"""Per-session metrics: the registry (`registry`), what a metric reads (`context`), the metric groups
(`motion`, `insertion`, `force`, `tissue`, `placement`, `subordinate_hand`: one module each, listed
in :data:`metrics.session.compute.METRIC_GROUPS`), computing them for sessions (`compute`, `batch`
on Dask) and the events in a supervisor's words (`events`)."""
