"""Signal processing the metrics read: kinematics (filtered speeds, smoothness), stitch placement,
the needle's passage, tissue stress and strain, and aligning streams in time."""
