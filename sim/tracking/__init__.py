"""Instruments tracked by a camera: calibration, printed markers, pose, filtering, pivot calibration.

One detector, pose and filter serve both the bench-video importer (``metrics.bench``) and the live
camera device (:mod:`sim.devices.camera`), so a recorded video and a webcam give the same poses.
"""
