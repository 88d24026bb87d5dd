"""Replay overlays: what a trainee did differently from an expert, as frames, plots and video.

- :mod:`metrics.replay.track`: a recorded session re-simulated frame by frame (needle,
  tissue drive, force) through the same runtime, deterministically;
- :mod:`metrics.replay.reference`: an expert reference from one or several expert
  sessions, aligned to the session under review (phases + DTW), with median and IQR bands;
- :mod:`metrics.replay.plots`: force, tip speed and stress vs time against the expert band;
- :mod:`metrics.replay.hud` and :mod:`metrics.replay.video`: the heads-up panel and the
  H.264/VP9 encoder; :mod:`metrics.replay.export` puts them together.

Rendering needs VTK (imported only when frames are drawn), encoding needs PyAV.
"""
