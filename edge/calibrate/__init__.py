"""Calibration of the event camera on the glasses: ``calibration.json`` from short captures.

``event_image`` (bursts -> detector-ready images), ``markers`` (boards and ArUco/ChArUco
detection), ``cameras`` (pinhole and Aria Fisheye624 models), ``intrinsics``, ``clock`` (flash
alignment and gaze-activity refinement), ``extrinsics`` (``T_event_cpf``; homography fallback),
``capture`` (capture folders, burst/frame pairing), ``check`` (the check picture), ``sensor_fit``,
``sensor`` and ``sensor_profile`` (K and the background curve: the sensor profile), ``cli``
(``darkread calibrate ...``). See docs/calibration.md.
"""
