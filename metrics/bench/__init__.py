"""Bench-model sessions from video: camera calibration (ChArUco), ArUco tracking of the needle holder,
and the tracked tool path as session streams for the same motion metrics as the simulator."""
